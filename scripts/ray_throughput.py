"""Throughput of `--executor ray` with 1 and with 2 workers on this machine (docs/scale.md).

Starts a local Ray instance with 2 CPUs, warms both workers up (imports, learned model), then times
`v2c synth` of N scans and `v2c to-step` of M of them with at most 1 and at most 2 tasks in flight (the executor's
``jobs``), checks that both give the same files, and prints / writes a JSON record: wall seconds, scans per second,
the 2-worker speed-up, wall and median CPU seconds per scan on one worker, the load average before each run and the
workers' peak memory.

    PYTHONPATH=$PWD .venv/bin/python scripts/ray_throughput.py --synth 16 --to-step 8 --out /tmp/ray_tp \
        --json docs/figures/ray_throughput.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import sys
import time
from functools import partial
from pathlib import Path

from v2c.commands.to_step import _to_step_task
from v2c.executors import ExecutorConfig, run_tasks
from v2c.synth.dataset import SynthConfig, generate_dataset, generate_scan


def _digest(folder: Path, skip_suffixes: tuple[str, ...] = ()) -> str:
    """SHA-1 over every file of a folder (relative path + bytes), leaving out files with the given suffixes."""
    h = hashlib.sha1()
    for p in sorted(folder.rglob("*")):
        if p.is_file() and not p.name.endswith(skip_suffixes):
            h.update(p.relative_to(folder).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def _timed(fn, item) -> tuple[float, float]:
    """Run ``fn(item)`` in the worker; (wall s, CPU s of this process) it took. The CPU seconds are what one free
    core needs for the scan, whatever else shares the machine."""
    t, c = time.perf_counter(), time.process_time()
    fn(item)
    return time.perf_counter() - t, time.process_time() - c


def _synth_one(args: tuple) -> None:
    generate_scan(*args)


def _median(values: list[float]) -> float:
    v = sorted(values)
    return 0.5 * (v[(len(v) - 1) // 2] + v[len(v) // 2]) if v else float("nan")


def _peak_rss_mib(_: int) -> tuple[int, float]:
    """(pid, peak resident memory in MiB) of the worker process running this task."""
    time.sleep(0.5)  # hold this worker so that the other task lands on the other one
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return os.getpid(), int(line.split()[1]) / 1024.0
    return os.getpid(), float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--synth", type=int, default=16, help="scans generated per run")
    ap.add_argument("--to-step", type=int, default=8, help="scans reconstructed per run")
    ap.add_argument("--size", default="640x480", help="scan size WxH (pixels)")
    ap.add_argument("--segmentation", default="learned", help="to-step segmentation")
    ap.add_argument("--out", type=Path, required=True, help="scratch folder (emptied)")
    ap.add_argument("--json", type=Path, default=None, help="write the record here")
    args = ap.parse_args()

    import ray

    w, h = (int(v) for v in args.size.split("x"))
    cfg = SynthConfig(width=w, height=h)
    shutil.rmtree(args.out, ignore_errors=True)
    args.out.mkdir(parents=True)
    t = time.perf_counter()
    ray.init(num_cpus=2, include_dashboard=False)
    record: dict = {
        "ray": ray.__version__,
        "cpus": os.cpu_count(),
        "size": [w, h],
        "segmentation": args.segmentation,
        "ray_init_s": time.perf_counter() - t,
        "started_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
    }

    def step_task(out: Path):
        return partial(
            _to_step_task, out=out, batch=True, frame="part", segmentation=args.segmentation, extras=True, roi=None
        )

    # warm-up: both workers import the stack and load the model before anything is timed
    warm = generate_dataset(args.out / "warm", 4, 99, cfg, progress=False, executor=ExecutorConfig("ray", jobs=2))
    assert all(
        exc is None for _, _, exc in run_tasks(step_task(args.out / "warm_steps"), warm, ExecutorConfig("ray", jobs=2))
    )
    runs: dict = {}
    for workers in (1, 2):
        where = ExecutorConfig("ray", jobs=workers)
        load = os.getloadavg()[0]
        folder = args.out / f"synth_{workers}"
        folder.mkdir()
        t = time.perf_counter()
        res = list(run_tasks(partial(_timed, _synth_one), [(folder, 0, i, cfg) for i in range(args.synth)], where))
        synth_s = time.perf_counter() - t
        synth_failed = [str(item[2]) for item, _, exc in res if exc is not None]
        synth_cpu = [r[1] for _, r, exc in res if exc is None]
        scans = sorted(folder.iterdir())[: args.to_step]
        load2 = os.getloadavg()[0]
        t = time.perf_counter()
        res = list(run_tasks(partial(_timed, step_task(args.out / f"steps_{workers}")), scans, where))
        steps_s = time.perf_counter() - t
        failed = [str(item) for item, _, exc in res if exc is not None]
        step_cpu = [r[1] for _, r, exc in res if exc is None]
        runs[workers] = {
            "synth_s": synth_s,
            "synth_scans_per_s": args.synth / synth_s,
            "synth_load1": load,
            "synth_cpu_s_median": _median(synth_cpu),
            "synth_failed": synth_failed,
            "to_step_s": steps_s,
            "to_step_scans_per_s": args.to_step / steps_s,
            "to_step_load1": load2,
            "to_step_cpu_s_median": _median(step_cpu),
            "to_step_failed": failed,
        }
        print(
            f"{workers} worker(s): synth {args.synth} scans {synth_s:.1f} s (load {load:.2f}), "
            f"to-step {args.to_step} scans {steps_s:.1f} s (load {load2:.2f})",
            file=sys.stderr,
        )
    record["runs"] = runs
    record["synth_speedup"] = runs[1]["synth_s"] / runs[2]["synth_s"]
    record["to_step_speedup"] = runs[1]["to_step_s"] / runs[2]["to_step_s"]
    record["synth_s_per_scan_1_worker"] = runs[1]["synth_s"] / args.synth
    record["to_step_s_per_scan_1_worker"] = runs[1]["to_step_s"] / args.to_step
    record["load1_end"] = os.getloadavg()[0]
    record["same_synth_files"] = _digest(args.out / "synth_1") == _digest(args.out / "synth_2")
    # STEP headers carry a timestamp and the VB-Rep JSON timings: compare the figures byte for byte
    record["same_to_step_figures"] = _digest(args.out / "steps_1", (".step", ".json")) == _digest(
        args.out / "steps_2", (".step", ".json")
    )
    peak = dict(ray.get([ray.remote(_peak_rss_mib).remote(i) for i in range(2)]))
    record["worker_peak_rss_mib"] = sorted(peak.values())
    record["finished_utc"] = time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime())
    ray.shutdown()
    text = json.dumps(record, indent=1)
    print(text)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
