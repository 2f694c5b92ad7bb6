"""The layer contract of docs/ARCHITECTURE.md, the typed stage inputs, one pipeline entry point and one default
segmentation: checked here so a change that breaks them fails the suite (and `make lint` fails before it)."""

from __future__ import annotations

import inspect
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _lint_imports() -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("lint-imports")
    if not exe.exists():
        pytest.skip("import-linter is not installed (pip install -e '.[dev]')")
    return subprocess.run([str(exe), "--no-cache"], cwd=REPO, capture_output=True, text=True, timeout=300)


def test_import_contracts_kept() -> None:
    res = _lint_imports()
    out = res.stdout + res.stderr
    assert res.returncode == 0, out[-4000:]
    # every contract of pyproject.toml ran and was kept: layers, acyclic siblings, fixtures on public APIs
    assert "Contracts: 3 kept, 0 broken." in out, out[-4000:]


def test_no_import_circle_between_modules() -> None:
    """No module imports itself back through others (a strongly connected component of more than one module)."""
    import grimp

    graph = grimp.build_graph("v2c", "exporters", "fixtures_design")
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.find_modules_directly_imported_by(v):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                circles.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for m in sorted(graph.modules):
        if m not in index:
            visit(m)
    assert circles == []


@pytest.mark.parametrize(
    ("module", "function", "params"),
    [
        ("v2c.pipeline", "reconstruct", {"scan": "Scan", "segmentation": "Segmentation"}),
        ("v2c.segment", "segment", {"scan": "Scan"}),
        ("v2c.fit", "fit_scan", {"scan": "Scan", "seg": "Segmentation"}),
        ("v2c.vbrep.extract", "extract_vbrep", {"scan": "Scan", "seg": "Segmentation", "fit": "FitResult"}),
    ],
)
def test_stage_inputs_are_typed(module: str, function: str, params: dict[str, str]) -> None:
    import importlib

    fn = getattr(importlib.import_module(module), function)
    sig = inspect.signature(fn)
    for name, want in params.items():
        ann = str(sig.parameters[name].annotation)
        assert want in ann and "Any" not in ann and ann != "object", f"{module}.{function}({name}: {ann})"


def test_one_reconstruct_and_pipeline_config() -> None:
    import v2c
    from v2c import api, pipeline
    from v2c.fit.config import FitConfig
    from v2c.segment.refine import RefineConfig
    from v2c.vbrep.config import VBRepConfig

    assert api.reconstruct is pipeline.reconstruct is v2c.reconstruct
    cfg = pipeline.PipelineConfig()
    assert isinstance(cfg.refine, RefineConfig) and isinstance(cfg.fit, FitConfig)
    assert isinstance(cfg.vbrep, VBRepConfig)
    assert inspect.signature(api.scan_to_step).parameters["config"].default is None


def test_pipeline_config_reaches_every_stage(monkeypatch: pytest.MonkeyPatch) -> None:
    """The stage configs of one PipelineConfig are the objects each stage receives (none is rebuilt inline)."""
    import v2c.fit
    import v2c.segment
    import v2c.vbrep.extract
    from v2c import pipeline
    from v2c.scan import load_scan

    seen: dict[str, object] = {}
    real_segment, real_fit, real_extract = v2c.segment.segment, v2c.fit.fit_scan, v2c.vbrep.extract.extract_vbrep

    def segment(scan: object, method: str, **kw: object) -> object:
        seen["refine"], seen["ransac"] = kw.get("refine"), kw.get("ransac")
        return real_segment(scan, method, **kw)

    def fit_scan(scan: object, seg: object, config: object, **kw: object) -> object:
        seen["fit"] = config
        return real_fit(scan, seg, config, **kw)

    def extract(scan: object, seg: object, fit: object, config: object) -> object:
        seen["vbrep"] = config
        return real_extract(scan, seg, fit, config)

    monkeypatch.setattr(v2c.segment, "segment", segment)
    monkeypatch.setattr(v2c.fit, "fit_scan", fit_scan)
    monkeypatch.setattr(v2c.vbrep.extract, "extract_vbrep", extract)
    cfg = pipeline.PipelineConfig()
    vb = pipeline.reconstruct(load_scan(REPO / "samples" / "bracket_planes_cylinders"), "oracle", config=cfg)
    want = {"refine": cfg.refine, "ransac": cfg.fit, "fit": cfg.fit, "vbrep": cfg.vbrep}
    assert set(seen) == set(want) and all(seen[k] is v for k, v in want.items()), seen
    assert len(vb.faces) >= 4


def test_one_default_segmentation() -> None:
    from v2c.choices import DEFAULT_SEGMENTATION
    from v2c.segment import segment

    assert DEFAULT_SEGMENTATION == "learned"
    assert inspect.signature(segment).parameters["method"].default == DEFAULT_SEGMENTATION
