"""Generalisation suites of `v2c bench`: parts the method never saw (issue 15 item 1, issue 16 item 4).

``--suite family`` is the in-family benchmark of `v2c.bench.run` (the six generator families or ``--cad DIR``),
unchanged. The suites here render parts that no training run and no threshold choice may see:

- ``unseen``: the **test** split of the CAD corpus (``../shared/data/cad_corpus``, split by file SHA-1 in
  ``v2c/synth/splits/cad_corpus.csv``, `v2c.synth.corpus`) and the **leave-out generator families** (`unseen_families`);
- ``corpus-val``: the **validation** split of the corpus, the only split anyone may tune on.
- ``corpus-train``: the **training** split (what a model or a calibration map may be fitted on; never reported
  as generalisation).

Scans. Every corpus part is rendered exactly as ``v2c synth --cad`` renders a STEP part (`v2c.synth.dataset`,
family ``cad``: OCCT reads the file in millimetres, the part rests on its largest hull facet, a random scene),
``views`` views per part. View v of a part is a pure function of (seed, the file's SHA-1, v): its generator seed
is `derived_seed` (seed, SHA-1) and its index v, so adding views or parts never changes a scan already made, and
views of different parts are drawn independently. A leave-out family gets ``family_scans`` scans the same way,
keyed by (seed, family name). Scans are cached under ``<cache>/suite_<noise>_<W>x<H>_s<seed>_<digest>/``
(``corpus/<file stem>_<sha1[:8]>/scan_0000v``, ``family/<name>/scan_0000i``; digest: generator version, noise,
size, seed), so a repeated run renders nothing; the cache lives outside the repository.

Report. Every scan is reconstructed and scored as in the family suite (`v2c.bench.workers.evaluate_dirs`: the same
metrics, the same to-step timing), then summarised per source (corpus split, every leave-out family, the families
together) and, for the corpus, per part size band (`BandConfig`: the file's face count under 30, 30-100, over
100). Counts join the metrics: faces the STEP build bounded by their mesh outline
(`exporters.step.StepReport.fallback_faces`), the STEP read back through OCCT (faces within 2 % of their mesh area,
the file's bounding box over the reconstruction's; `v2c.bench.workers`) and failures (a scan that raised anywhere,
rendering included: counted and named, never stopping the run).
"""

from __future__ import annotations

import hashlib
import json
import math
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from v2c.bench.cache import default_cache_dir, scan_complete
from v2c.bench.config import GT, BenchConfig, columns_of
from v2c.bench.tables import format_value, jsonable, summarise
from v2c.bench.workers import error_text, evaluate_dirs, failed_rows, precision_of, process_start_seconds
from v2c.synth.corpus import SPLIT_FILE, CorpusPart, checked_files, default_corpus_dir, read_split

if TYPE_CHECKING:
    from v2c.synth.dataset import SynthConfig

#: Suite name -> the corpus split it renders (None: the family suite of `v2c.bench.run`).
SUITES: dict[str, str | None] = {"family": None, "unseen": "test", "corpus-val": "val", "corpus-train": "train"}
#: Suites that add the leave-out generator families (tuning suites never do: those families are for testing).
SUITES_WITH_FAMILIES = ("unseen",)
#: Where the leave-out family names come from: (module, constant). The feature generator (branch ``gen``) defines
#: them; until it is merged the suite runs without that source and says so.
UNSEEN_FAMILIES_SOURCE = ("v2c.synth.families", "LEAVE_OUT_FAMILIES")
SUITE_GENERATOR = "v2c.bench.suite/1"  # bump when the way suite scans are drawn changes (invalidates the cache)

CORPUS = "corpus"
FAMILY = "family"

#: Part sizes: a STEP file whose largest vertex or edge tolerance exceeds this bridges a visible gap (faces that
#: should meet lie this far apart); counted per group. Issue 16's bound for a tangent edge's place (1 % of the part
#: size), not tuned.
TOLERANCE_GAP_REL = 0.01


@dataclass(frozen=True)
class BandConfig:
    """Part size bands of the corpus by the file's face count (faces of the STEP as OCCT reads it)."""

    small_below: int = 30  # faces: a part with fewer faces is "small" (< 30)
    large_above: int = 100  # faces: a part with more faces is "large" (> 100); the rest is 30-100


def band_of(n_faces: int, bands: BandConfig = BandConfig()) -> str:
    """The size band label of a part with ``n_faces`` faces: ``<30``, ``30-100`` or ``>100`` (bounds of ``bands``)."""
    if n_faces < bands.small_below:
        return f"<{bands.small_below}"
    if n_faces > bands.large_above:
        return f">{bands.large_above}"
    return f"{bands.small_below}-{bands.large_above}"


def band_labels(bands: BandConfig = BandConfig()) -> tuple[str, str, str]:
    """The three band labels, smallest first."""
    return (
        band_of(bands.small_below - 1, bands),
        band_of(bands.small_below, bands),
        band_of(bands.large_above + 1, bands),
    )


@dataclass(frozen=True)
class SuiteConfig:
    """One run of a generalisation suite. ``bench`` carries what the family suite has too (seed, noise, size
    (width, height) pixels, segmentations, ablations, jobs, cache folder, STEP export, metrics, figures,
    weights); its ``n``, ``cad_dir`` and ``scans_dir`` are not used."""

    suite: str = "unseen"
    bench: BenchConfig = field(default_factory=lambda: BenchConfig(ablations=("full",)))
    corpus_dir: Path | None = None  # None: default_corpus_dir()
    split_file: Path = SPLIT_FILE
    views: int = 2  # rendered views per corpus part
    parts: tuple[str, ...] | None = None  # only these corpus files (names in the split); None: the whole split
    families: tuple[str, ...] | None = None  # leave-out families; None: unseen_families()
    family_scans: int = 16  # scans per leave-out family (3 x 16 + 28 parts x 2 views = 104 scans: issue 15 asks >= 100)
    bands: BandConfig = field(default_factory=BandConfig)
    appearance: str = "plain"  # "random": appearance and framing randomization (v2c.synth.appearance)

    @property
    def corpus_split(self) -> str | None:
        """The corpus split this suite renders (train / val / test), None for the family suite."""
        return SUITES[self.suite]


# --------------------------------------------------------------------------------------------------- sources


def corpus_parts(cfg: SuiteConfig) -> list[CorpusPart]:
    """The corpus files of the suite's split (only ``cfg.parts`` if given), checked against the corpus folder:
    each file must exist and have the SHA-1 the split was made from. Raises ValueError naming the file."""
    split = cfg.corpus_split
    if split is None:
        return []
    rows = [p for p in read_split(cfg.split_file) if p.split == split]
    if cfg.parts is not None:
        known = {p.file for p in rows}
        bad = [f for f in cfg.parts if f not in known]
        if bad:
            raise ValueError(f"{cfg.split_file}: {', '.join(bad)} not in the {split} split")
        rows = [p for p in rows if p.file in cfg.parts]
    if rows:  # none asked for (--parts none): the corpus folder is not needed
        checked_files(rows, cfg.corpus_dir, cfg.split_file)
    return rows


def unseen_families() -> tuple[tuple[str, ...], str | None]:
    """The leave-out generator families (`UNSEEN_FAMILIES_SOURCE`) and a note when there are none: the module
    is not there (the feature generator is not merged yet) or defines no such constant."""
    import importlib

    module, name = UNSEEN_FAMILIES_SOURCE
    try:
        mod = importlib.import_module(module)
    except ImportError:
        return (), f"leave-out families skipped: no {module} yet (the feature generator defines {name})"
    names = tuple(getattr(mod, name, ()) or ())
    if not names:
        return (), f"leave-out families skipped: {module} defines no {name}"
    return names, None


def known_families() -> set[str]:
    """Family names the scan generator can draw (`v2c.synth.families`: procedural and feature-based)."""
    from v2c.synth.families import FEATURE_FAMILIES, PROCEDURAL_FAMILIES

    return set(PROCEDURAL_FAMILIES) | set(FEATURE_FAMILIES)


def derived_seed(seed: int, key: str) -> int:
    """The generator seed of one part's (or family's) scans: 32 bits of SHA-1("<seed>:<key>")."""
    return int(hashlib.sha1(f"{seed}:{key}".encode()).hexdigest()[:8], 16)


def suite_cache_dir(cfg: SuiteConfig) -> Path:
    """The cache root of the suite's scans: named by noise, size and seed, suffixed with a hash of everything
    that changes a scan besides its part (generator and suite versions, noise, size, seed; appearance and framing
    version unless plain)."""
    from v2c.synth.dataset import GENERATOR

    b = cfg.bench
    key = {"generator": GENERATOR, "suite": SUITE_GENERATOR, "noise": b.noise, "size": list(b.size), "seed": b.seed}
    look = ""
    if cfg.appearance != "plain":  # plain keeps the digest (and cache) it had before appearances existed
        from v2c.synth.appearance import FRAMING_VERSION  # these suites frame by extent (plan_scans)

        key["appearance"] = cfg.appearance
        key["framing"] = FRAMING_VERSION
        look = f"_{cfg.appearance}"
    digest = hashlib.sha1(json.dumps(key, sort_keys=True).encode()).hexdigest()[:8]
    return (b.cache_dir or default_cache_dir()) / f"suite_{b.noise}_{b.size[0]}x{b.size[1]}_s{b.seed}{look}_{digest}"


@dataclass
class SuiteScan:
    """One scan of the suite: its folder, where it comes from and how to render it."""

    path: Path
    source: str  # CORPUS or FAMILY
    name: str  # corpus file name or family name
    view: int
    seed: int  # generator seed (`derived_seed`); the scan's index is ``view``
    synth: SynthConfig  # how the generator renders it
    n_faces: int | None = None  # corpus: faces of the file
    band: str | None = None  # corpus: size band

    @property
    def label(self) -> str:
        """A readable unique name: ``<file or family>/v<view>``."""
        return f"{self.name}/v{self.view}"


def plan_scans(cfg: SuiteConfig) -> tuple[list[SuiteScan], list[str]]:
    """Every scan of the suite (corpus parts by file name, view by view; then the leave-out families) and notes
    about skipped sources."""
    from v2c.synth.dataset import SynthConfig, scan_name

    b = cfg.bench
    root = suite_cache_dir(cfg)
    base = SynthConfig(
        width=b.size[0],
        height=b.size[1],
        noise=b.noise,
        **({"appearance": cfg.appearance, "framing": "extent"} if cfg.appearance != "plain" else {}),
    )
    folder = Path(cfg.corpus_dir or default_corpus_dir())
    scans: list[SuiteScan] = []
    notes: list[str] = []
    for p in corpus_parts(cfg):
        synth = replace(base, families=("cad",), cad_files=(str((folder / p.file).resolve()),))
        seed = derived_seed(b.seed, p.sha1)
        part_dir = root / CORPUS / f"{Path(p.file).stem}_{p.sha1[:8]}"
        scans += [
            SuiteScan(part_dir / scan_name(v), CORPUS, p.file, v, seed, synth, p.n_faces, band_of(p.n_faces, cfg.bands))
            for v in range(cfg.views)
        ]
    if cfg.suite in SUITES_WITH_FAMILIES:
        names = cfg.families
        if names is None:
            names, note = unseen_families()
            if note:
                notes.append(note)
        known = known_families()
        for name in names:
            if name not in known:
                notes.append(
                    f"leave-out family {name!r} skipped: the generator does not know it "
                    f"(known: {', '.join(sorted(known))})"
                )
                continue
            synth = replace(base, families=(name,))
            seed = derived_seed(b.seed, f"family:{name}")
            scans += [
                SuiteScan(root / FAMILY / name / scan_name(i), FAMILY, name, i, seed, synth)
                for i in range(cfg.family_scans)
            ]
    return scans, notes


def _render(args: tuple[Path, int, int, SynthConfig]) -> str | None:
    """Render one scan into its folder (`v2c.synth.dataset.generate_scan`); the error text if it raised."""
    from v2c.synth.dataset import generate_scan

    out_dir, seed, index, synth = args
    try:
        generate_scan(out_dir, seed, index, synth)
        return None
    except Exception as exc:  # noqa: BLE001 - a part that cannot be rendered is a named failure of the suite
        return error_text(exc)


def render_missing(scans: Sequence[SuiteScan], jobs: int, progress: bool = True) -> dict[str, str]:
    """Render the scans not yet in the cache (``jobs`` spawned processes); returns label -> error for those that
    failed. A scan is complete once its ``gt/meta.json`` exists (the generator writes it last)."""
    from tqdm import tqdm

    from v2c.synth.dataset import _worker_init

    todo = [s for s in scans if not scan_complete(s.path)]
    errors: dict[str, str] = {}
    if not todo:
        return errors
    if progress:
        print(f"rendering {len(todo)} of {len(scans)} suite scans into {suite_root(scans)}", file=sys.stderr)
    tasks = [(s.path.parent, s.seed, s.view, s.synth) for s in todo]
    bar = tqdm(total=len(tasks), unit="scan", desc="render", disable=not progress)
    if jobs <= 1:
        _worker_init()
        results = map(_render, tasks)
        for s, err in zip(todo, results, strict=True):
            if err:
                errors[s.label] = err
            bar.update()
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = mp.get_context("spawn")  # forking a process whose embree/OCCT pools run deadlocks
        with ProcessPoolExecutor(max_workers=jobs, initializer=_worker_init, mp_context=ctx) as pool:
            futures = {pool.submit(_render, t): s for t, s in zip(tasks, todo, strict=True)}
            for fut in as_completed(futures):
                try:
                    err = fut.result()
                except Exception as exc:  # noqa: BLE001 - the worker died (a crash inside OCCT)
                    err = error_text(exc)
                if err:
                    errors[futures[fut].label] = err
                bar.update()
    bar.close()
    return errors


def suite_root(scans: Sequence[SuiteScan]) -> Path | None:
    """The cache root the scans lie under."""
    return scans[0].path.parent.parent.parent if scans else None


# ------------------------------------------------------------------------------------------------------ run


def run_suite(cfg: SuiteConfig, progress: bool = True) -> dict[str, Any]:
    """Plan, render what is missing, reconstruct and score every scan, summarise per group. Returns the
    JSON-able result: ``config``, ``suite``, ``notes``, ``scans`` (per scan: path, source, name, view, band),
    ``columns``, ``groups``, ``summary`` {column: {group: {...}}}, ``rows``, ``process_start_s``, ``wall_s``."""
    t0 = time.perf_counter()
    if cfg.corpus_split is None:
        raise ValueError("the family suite runs through v2c.bench.run.run_benchmark")
    b = cfg.bench
    scans, notes = plan_scans(cfg)
    if not scans:
        raise ValueError(f"suite {cfg.suite}: no scans ({'; '.join(notes) or 'no parts'})")
    render_errors = render_missing(scans, b.jobs, progress)
    ok = [s for s in scans if s.label not in render_errors]
    figure_dirs = [Path(b.figure_dir) / s.source / s.path.parent.name if b.figure_dir else None for s in ok]
    rows = evaluate_dirs(b, [s.path for s in ok], progress, figure_dirs, desc=f"bench {cfg.suite}")
    weights = str(b.weights) if b.weights else None
    for s in scans:
        if s.label in render_errors:
            rows += failed_rows(
                (str(s.path), tuple(b.segmentations), tuple(b.ablations)), f"render: {render_errors[s.label]}"
            )
    by_path = {str(s.path): s for s in scans}
    order = {str(s.path): i for i, s in enumerate(scans)}
    rows.sort(key=lambda r: order.get(r["path"], 0))
    for r in rows:
        s = by_path[r["path"]]
        r.update(source=s.source, part=s.name, view=s.view, band=s.band, n_faces=s.n_faces, label=s.label)
    start = process_start_seconds([m for m in b.segmentations if m != GT], weights)
    cols = [f"{s}/{a}" for s, a in columns_of(b)]
    groups = group_names(cfg, scans)
    summary = {
        c: {g: summarise_group([r for r in rows if _column(r) == c and in_group(r, g, cfg)], start) for g in groups}
        for c in cols
    }
    conf = asdict(cfg)
    conf["bench"].update(
        weights=weights,
        cache_dir=str(suite_root(scans)),
        network_precision=precision_of(cfg.bench.segmentations),
    )
    conf["corpus_dir"] = str(cfg.corpus_dir or default_corpus_dir())
    conf["corpus_split"] = cfg.corpus_split
    return jsonable(
        {
            "config": conf,
            "suite": cfg.suite,
            "notes": notes,
            "scans": [
                {
                    "path": str(s.path),
                    "source": s.source,
                    "name": s.name,
                    "view": s.view,
                    "band": s.band,
                    "n_faces": s.n_faces,
                }
                for s in scans
            ],
            "columns": cols,
            "groups": groups,
            "summary": summary,
            "rows": rows,
            "process_start_s": start,
            "wall_s": time.perf_counter() - t0,
        }
    )


def _column(row: dict[str, Any]) -> str:
    return f"{row['segmentation']}/{row['ablation']}"


#: The group of every scan of a suite that holds both sources (issue 15 states its figures on the whole suite).
WHOLE_SUITE = "whole suite"


def group_names(cfg: SuiteConfig, scans: Sequence[SuiteScan]) -> list[str]:
    """The report's groups, in order: the corpus split, its size bands, every leave-out family, the families
    together (only sources with scans), and `WHOLE_SUITE` when both sources have scans."""
    out: list[str] = []
    corpus = any(s.source == CORPUS for s in scans)
    if corpus:
        out.append(f"corpus {cfg.corpus_split}")
        out += [f"corpus {cfg.corpus_split} {b}" for b in band_labels(cfg.bands)]
    fams = list(dict.fromkeys(s.name for s in scans if s.source == FAMILY))
    out += [f"family {f}" for f in fams]
    if fams:
        out.append("leave-out families")
    if corpus and fams:
        out.append(WHOLE_SUITE)
    return out


def in_group(row: dict[str, Any], group: str, cfg: SuiteConfig) -> bool:
    """Whether a tagged row belongs to a group of `group_names`."""
    if group == WHOLE_SUITE:
        return row.get("source") in (CORPUS, FAMILY)
    if group == "leave-out families":
        return row.get("source") == FAMILY
    if group.startswith("family "):
        return row.get("source") == FAMILY and row.get("part") == group[len("family ") :]
    whole = f"corpus {cfg.corpus_split}"
    if row.get("source") != CORPUS or not group.startswith(whole):
        return False
    return group == whole or group == f"{whole} {row.get('band')}"


def summarise_group(rows: list[dict[str, Any]], process_start_s: float = float("nan")) -> dict[str, Any]:
    """`v2c.bench.run.summarise` of a group's rows, plus: ``parts`` (distinct parts or families),
    ``fallback_faces`` / ``step_faces`` (sums over the scans that wrote a STEP), ``fallback_per_scan`` (mean),
    ``area_ok_faces`` / ``area_faces`` (faces read back within 2 % of their mesh area and meshed by OCCT / faces
    read back), ``unmeshed_faces`` (faces in the file that OCCT's mesher draws short: holes in a viewer),
    ``box_ratio_min`` / ``box_ratio_max`` (the STEP's largest bounding-box extent over the reconstruction's),
    ``tol_rel_median`` / ``tol_rel_max`` (the file's largest vertex or edge tolerance in part sizes, median and
    largest over scans) and ``tol_over`` (scans whose file bridges a gap over ``TOLERANCE_GAP_REL``),
    ``chamfer_max`` (the worst scan), ``failures`` (every failed scan: label and error)."""
    out = summarise(rows, process_start_s)
    ok = [r for r in rows if r.get("ok")]
    stepped = [r for r in ok if r.get("step_faces") is not None]
    out["parts"] = len({r["part"] for r in rows})
    out["fallback_faces"] = int(sum(r.get("step_fallback_faces", 0) for r in stepped))
    out["step_faces"] = int(sum(r["step_faces"] for r in stepped))
    out["fallback_per_scan"] = (out["fallback_faces"] / len(stepped)) if stepped else float("nan")
    read = [r for r in stepped if r.get("step_area_faces") is not None]
    out["area_ok_faces"] = int(sum(r["step_area_ok_faces"] for r in read))
    out["area_faces"] = int(sum(r["step_area_faces"] for r in read))
    out["unmeshed_faces"] = int(sum(r.get("step_unmeshed_faces", 0) for r in read))
    ratios = [r["step_box_ratio"] for r in read if math.isfinite(r.get("step_box_ratio", math.nan))]
    out["box_ratio_max"] = max(ratios) if ratios else float("nan")
    out["box_ratio_min"] = min(ratios) if ratios else float("nan")
    tols = [r["step_max_tol_rel"] for r in read if math.isfinite(r.get("step_max_tol_rel", math.nan))]
    out["tol_rel_median"] = float(statistics.median(tols)) if tols else float("nan")
    out["tol_rel_max"] = max(tols) if tols else float("nan")
    out["tol_over"] = sum(t > TOLERANCE_GAP_REL for t in tols)
    ch = [r["chamfer"] for r in ok if r.get("chamfer") is not None and math.isfinite(r["chamfer"])]
    out["chamfer_max"] = max(ch) if ch else float("nan")
    out["failures"] = [{"scan": r["label"], "error": r["error"]} for r in rows if not r.get("ok")]
    return out


# ---------------------------------------------------------------------------------------------- the tables

#: (row title, summary key, format) of a suite table.
SUITE_ROWS: tuple[tuple[str, str, str], ...] = (
    ("face precision @ IoU 0.5", "precision", "pct"),
    ("face recall @ IoU 0.5 (gt faces >= 50 px)", "recall", "pct"),
    ("face recall @ IoU 0.5, all gt faces", "recall_all", "pct"),
    ("type accuracy", "type_accuracy", "pct"),
    ("axis accuracy", "axis_accuracy", "pct"),
    ("primitive alignment (lower is better)", "alignment", "f4"),
    ("Chamfer distance, visible R (lower is better)", "chamfer", "f4"),
    ("Chamfer distance, worst scan", "chamfer_max", "f4"),
    ("edge-type accuracy", "edge_type_accuracy", "pct"),
    ("farthest face from the measured part points (part sizes, any scan)", "face_far_max", "f4"),
    ("faces farther than 0.05 part sizes (all scans)", "faces_far", "int"),
    ("faces off the true visible surface by over 0.05 part sizes (all scans)", "faces_off_part", "int"),
    ("intersection-edge confidence ECE (10 bins)", "ece_intersection", "ece"),
    ("intersection-edge confidence ECE, raw factors", "ece_intersection_raw", "ece"),
    ("all-edge confidence ECE (10 bins)", "ece_all", "ece"),
    ("runtime per scan, median wall (s)", "runtime", "s"),
    ("runtime per scan, median CPU (s)", "runtime_cpu", "s"),
)


def format_suite_tables(result: dict[str, Any]) -> str:
    """One Markdown table per column (segmentation / ablation): rows = metrics and counts, columns = groups."""
    groups = result["groups"]
    out = []
    for col in result["columns"]:
        summ = result["summary"][col]
        seg, abl = col.split("/")
        out.append(f"{seg} segmentation, {abl}" if seg != GT else "ideal (gt VB-Rep)")
        out.append("")
        out.append("| metric | " + " | ".join(groups) + " |")
        out.append("| --- |" + " ---: |" * len(groups))
        for title, key, kind in SUITE_ROWS:
            out.append(f"| {title} | " + " | ".join(format_value(summ[g].get(key), kind) for g in groups) + " |")
        out.append(
            "| STEP faces bounded by their mesh outline / STEP faces | "
            + " | ".join(f"{summ[g]['fallback_faces']} / {summ[g]['step_faces']}" for g in groups)
            + " |"
        )
        out.append(
            "| mesh-outline faces per scan (mean) | "
            + " | ".join(_f2(summ[g]["fallback_per_scan"]) for g in groups)
            + " |"
        )
        out.append(
            "| STEP faces read back within 2 % of their mesh area / faces | "
            + " | ".join(f"{summ[g]['area_ok_faces']} / {summ[g]['area_faces']}" for g in groups)
            + " |"
        )
        out.append(
            "| STEP faces OCCT's mesher leaves short (holes in a viewer) | "
            + " | ".join(str(summ[g].get("unmeshed_faces", "")) for g in groups)
            + " |"
        )
        out.append(
            "| STEP / reconstruction bounding box, largest extent (min - max over scans) | "
            + " | ".join(f"{_f2(summ[g]['box_ratio_min'])} - {_f2(summ[g]['box_ratio_max'])}" for g in groups)
            + " |"
        )
        out.append(
            "| STEP's largest vertex / edge tolerance, part sizes (median ; max over scans ; scans over "
            f"{100 * TOLERANCE_GAP_REL:g} %) | "
            + " | ".join(
                f"{_f4(summ[g].get('tol_rel_median'))} ; {_f4(summ[g].get('tol_rel_max'))} ; "
                f"{summ[g].get('tol_over', '')}"
                for g in groups
            )
            + " |"
        )
        out.append("| failures (scans that raised) | " + " | ".join(str(summ[g]["failed"]) for g in groups) + " |")
        out.append("| scans (parts) | " + " | ".join(f"{summ[g]['scans']} ({summ[g]['parts']})" for g in groups) + " |")
        out.append("")
    return "\n".join(out).rstrip()


def _f4(v: Any) -> str:
    return "" if v is None or not math.isfinite(v) else f"{v:.4f}"


def _f2(v: Any) -> str:
    return "" if v is None or not math.isfinite(v) else f"{v:.2f}"


def worst_scans(result: dict[str, Any], column: str, k: int = 8) -> list[dict[str, Any]]:
    """The ``k`` worst scans of a column: failures first, then by recall, precision (lowest first), then
    Chamfer (highest first)."""
    rows = [r for r in result["rows"] if _column(r) == column]

    def key(r: dict[str, Any]) -> tuple:
        if not r.get("ok"):
            return (0, 0.0, 0.0, 0.0)
        ch = r.get("chamfer")
        return (1, r.get("recall") or 0.0, r.get("precision") or 0.0, -(ch if ch is not None else 0.0))

    return sorted(rows, key=key)[:k]


def format_suite_notes(result: dict[str, Any], worst: int = 8) -> str:
    """Lines under the tables: skipped sources, process start and wall time, every failure by scan, the worst
    scans per column."""
    out = list(result["notes"])
    out.append(
        f"process start (once per set): {result['process_start_s'] or float('nan'):.2f} s; benchmark wall "
        f"time {result['wall_s']:.0f} s"
    )
    for col in result["columns"]:
        fails = [r for r in result["rows"] if _column(r) == col and not r.get("ok")]
        out.append(f"{col}: {len(fails)} failed" + (":" if fails else ""))
        out += [f"  {r['label']} ({r['scan']}): {r['error']}" for r in fails]
        if worst:
            out.append(f"{col}: worst scans")
            for r in worst_scans(result, col, worst):
                if not r.get("ok"):
                    continue
                out.append(f"  {r['label']}" + (f" [{r['band']}]" if r.get("band") else "") + ": " + _worst_line(r))
    return "\n".join(out)


def _worst_line(r: dict[str, Any]) -> str:
    """One worst scan's figures; a figure the scan has none of (no matched face, no STEP written) is "n/a"."""

    def fv(key: str, kind: str) -> str:
        v = r.get(key)
        return "n/a" if v is None else format_value(v, kind)

    outline = (
        f"{r['step_fallback_faces']} of {r['step_faces']}"
        if r.get("step_faces") is not None and r.get("step_fallback_faces") is not None
        else "n/a (no STEP)"
    )
    t = r.get("runtime", {}).get("to_step")
    return (
        f"precision {fv('precision', 'pct')}, recall {fv('recall', 'pct')}, type {fv('type_accuracy', 'pct')}, "
        f"alignment {fv('alignment', 'f4')}, Chamfer {fv('chamfer', 'f4')}, mesh-outline faces {outline}, "
        + ("n/a s" if t is None else f"{format_value(t, 's')} s")
    )


def run_and_report(cfg: SuiteConfig, progress: bool = True, echo: Callable[[str], None] = print) -> dict[str, Any]:
    """`run_suite`, then print its header, tables and notes through ``echo``."""
    result = run_suite(cfg, progress)
    b = cfg.bench
    n_corpus = sum(1 for s in result["scans"] if s["source"] == CORPUS)
    n_fam = len(result["scans"]) - n_corpus
    echo(
        f"suite {cfg.suite}: {n_corpus} scans of {len({s['name'] for s in result['scans'] if s['source'] == CORPUS})}"
        f" corpus {cfg.corpus_split} parts ({cfg.views} views each), {n_fam} leave-out family scans; {b.noise} "
        f"noise, {b.size[0]}x{b.size[1]}, seed {b.seed}, appearance {cfg.appearance}, segmentation "
        f"{','.join(b.segmentations)}"
    )
    echo(format_suite_tables(result))
    echo(format_suite_notes(result))
    return result
