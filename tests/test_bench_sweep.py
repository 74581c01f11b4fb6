"""bench.convergence's sweep on a Dask LocalCluster: killed half-way, started again, it runs only
the cells that had not finished."""
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

from bench import convergence, reference, sweep
from tests import scenes

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_todo_leaves_out_the_cells_with_a_record():
    cells = [{"k": i} for i in range(4)]
    assert sweep.todo(cells, [{"k": 2}, {"k": 0}, {"k": 9}], lambda c: c["k"]) == [{"k": 1}, {"k": 3}]


def test_a_killed_sweep_resumes_without_rerunning_finished_cells(tmp_path):
    """The sweep (6 cells of 0.4 s on 2 pinned single-thread workers, restarted after 4) is killed with SIGKILL, the
    whole process group, once its first record is stored; records.jsonl must then hold whole
    records only. Run again, it must add exactly the missing cells: the records (their dates and
    timings) and images of the finished ones stay as they were, and every cell has one record.
    Detects a sweep that starts over, loses or duplicates records, or leaves a torn file; and
    workers that share cores (each record names the one core its render ran on)."""
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=8, height=8)
    ref_dir = tmp_path / "ref"
    assert reference.main([obj, "--spp", "16", "--out", str(ref_dir)]) == 0
    out = tmp_path / "conv"
    script = tmp_path / "sweep.py"
    script.write_text(textwrap.dedent(f"""
        from bench import common, convergence, sweep
        common.default_out = lambda path: {str(ref_dir)!r}
        sweep.FRESH_AFTER = 2  # the workers restarted after every 4 cells
        if __name__ == "__main__":  # the workers' processes import this file too
            raise SystemExit(convergence.main(["--scenes", {obj!r}, "--time", "0.4", "--seeds", "6",
                                               "--threads", "1", "--workers", "2", "--out", {str(out)!r}]))
    """))
    env = dict(os.environ, PYTHONPATH=ROOT)
    log = out / "records.jsonl"
    proc = subprocess.Popen([sys.executable, str(script)], cwd=ROOT, env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.monotonic()
    try:
        while not (log.exists() and log.read_text().strip()):
            assert proc.poll() is None, "the sweep ended before it stored a record"
            assert time.monotonic() - t0 < 240, "no record after 240 s"
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    first = [json.loads(line) for line in log.read_text().splitlines()]
    assert 1 <= len(first) < 6
    images = {r["image"]: os.stat(out / "images" / "box" / r["image"]).st_mtime_ns for r in first}

    done = subprocess.run([sys.executable, str(script)], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    recs = [json.loads(line) for line in log.read_text().splitlines()]
    assert recs[:len(first)] == first
    assert sorted(convergence.record_key(r)[2] for r in recs) == list(range(6))  # one record per seed
    for name, mtime in images.items():
        assert os.stat(out / "images" / "box" / name).st_mtime_ns == mtime
    if hasattr(os, "sched_getaffinity") and (os.cpu_count() or 1) >= 2:
        assert all(len(r["cores"]) == 1 for r in recs)
    assert os.path.isfile(out / "box_time.png") and "## box" in (out / "summary.md").read_text()
