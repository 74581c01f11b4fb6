"""Error against wall time and against samples, per scene and method, in one run on one machine.

    python -m bench.convergence --scenes ajar,cornell --methods bsdf --time 10,20,40,80 --seeds 3
    python -m bench.convergence --scenes veach-ajar --scene-dir ../shared/scenes --time 10,20
    python -m bench.convergence --scenes ajar --methods bsdf,photon,photon:mixing=variance

A method is a registered guide name, optionally with settings after a colon
(`name:key=value,key=value`, as `--guide-opt` takes them), so variants of one guide can be compared,
or a gradient-domain method (GRADIENT_METHODS: `gpt-l1`, `gpt-l2`, `gpt-replay-l1`, `gpt-gradnet`
(with eq. 13's energy correction), `gpt-gradnet-raw` (without): the integrator gpt with that shift
and reconstruction; its solve, or the network's inference, counts in its time).

A scene name is `scenes/<name>/<name>.obj`, or `<scene-dir>/<name>/scene.obj` for external
scenes; its reference is the one `python -m bench.reference` wrote (scenes/<name>/reference.exr,
or bench/results/references/<name>/ for external scenes). Every method runs at every time
budget and every spp budget (`--spp`, default: the spp that `bsdf` reached at each time
budget; bsdf is then not run again at them: its time runs are its points against spp), once
per seed. Writes to `--out` (default bench/results/convergence/):

    records.jsonl                 one JSON record per run: scene, method, settings, seed, spp,
                                  samples, wall time split into the guide's learning
                                  (`time_learning`), its map rebuild between passes (`update_s`),
                                  network inference (`inference_s`, 0 for guides without a
                                  network) and rendering; the shade stage's seconds (`shade_s`),
                                  guide memory, every metric against the reference
    <scene>_time.png, _spp.png    relMSE against wall time and against spp, log-log, one line
                                  per method (median over seeds, band from min to max)
    summary.md                    per scene, each method's error at equal time as a ratio to bsdf;
                                  each guide's shading cost over bsdf's (shade seconds per sample,
                                  median over seeds, minus bsdf's, in ns); learning, update time
                                  and memory at the largest budget
    images/<scene>/<run>.npy      every run's image (float32), so that the records can be scored
                                  again against a better reference later:

    python -m bench.convergence --rescore --out bench/results/convergence [--scene-dir ../shared/scenes]

re-reads the records and images in --out, recomputes every metric against the references as they
are now, and writes records, charts and summary again (no rendering). Records stored before
`update_s`, `shade_s` and `samples` were recorded still score: their update time is the old
`time_inference` (then a misnomer for the same rebuild), their shading cost is shown as "-".

Every output is written to a temporary file beside it and renamed into place (bench.atomic), so a
stopped run leaves complete files: records.jsonl is rewritten after every run.
"""
import argparse
import gc
import json
import os
import platform
import time

import numpy as np

import tracer
from tracer import metrics
from . import atomic
from . import sweep as sweep_module
from tracer.guiding import guide_names
from .common import DENOISED, GRADIENT_METHODS, check_method, method_spec, reference_for, render_args, scene_name, scene_path  # noqa: F401
from . import common
from .reference import ROOT
from .reference import load as load_reference

DEFAULT_OUT = os.path.join(ROOT, "bench", "results", "convergence")
# `--methods all`: every registered guide with the path tracer, the gradient-domain tracer with each
# reconstruction, and each of them denoised
_BASE_METHODS = tuple(guide_names()) + ("gpt-l1", "gpt-l2", "gpt-gradnet")
ALL_METHODS = _BASE_METHODS + tuple(m + DENOISED for m in _BASE_METHODS)
CHART_METRICS = ("relMSE", "1-SSIM")  # where denoisers and learned reconstructions differ: the second


# guide statistics a record keeps (pss: the chosen model and the share of zero-valued samples;
# odis: the pixels with a map, the gather window and how full it was)
GUIDE_STATS = ("m", "layers", "width", "parameters", "val_nll", "epochs", "fallback", "zero_share_uniform",
               "zero_share_final", "second_moment_ratio", "inference_us_per_sample", "candidates_lit",
               "pixels_guided", "pixels", "window", "centre_sparsity", "initial_lit", "lit_share", "switched_off",
               "voxels", "training", "choice", "why")


def run_one(scene, method, seed, ref, time_budget=None, spp=None, images=None, threads=None):
    """Render `method` once and score it against `ref`: its record (a denoised method is scored on
    its denoised image, which is the one stored)."""
    r = tracer.render(scene, spp=spp, time=time_budget, seed=seed, threads=threads, **render_args(method))
    final = r.image if r.denoised is None else r.denoised
    s = r.stats
    image = None
    if images:
        os.makedirs(images, exist_ok=True)
        tag = method.replace(":", "_").replace(",", "_").replace("=", "-").replace("/", "+")
        image = f"{tag}_{'t%g' % time_budget if time_budget else 'spp%d' % spp}_s{seed}.npy"
        atomic.save_npy(os.path.join(images, image), final.astype(np.float32))
    learning = s.get("guide_time_learning", 0.0)
    update = s.get("guide_time_update", 0.0)
    inference = s.get("guide_time_inference", 0.0)
    return {
        "method": method, "seed": seed, "budget": "time" if time_budget else "spp",
        "time_budget": time_budget, "spp": s["spp"], "samples": s["samples"],
        "time_total": s["time_total"], "time_learning": learning, "update_s": update, "inference_s": inference,
        "time_rendering": s["time_total"] - learning - update - inference - s.get("time_denoise", 0.0),
        "shade_s": s["time_stages"]["shade"] + s["time_trace_parts"]["shade"],  # wavefront + per-thread loop
        "solve_s": s.get("time_solve", 0.0),
        "guide_memory_bytes": s.get("guide_memory_bytes", 0),
        "settings": {k: s[k] for k in ("max_depth", "rr_depth", "accel", "threads", "pixel_filter")},
        "metrics": metrics.all_metrics(final, ref),
        "nonfinite_samples": s["nonfinite_samples"],
        "time_denoise": s.get("time_denoise", 0.0),
        "nonfinite_denoised": s.get("nonfinite_denoised", 0),
        "image": image,
        "guide_stats": {k: v for k, v in s.get("guide_stats", {}).items() if k in GUIDE_STATS},
    }


def _band(records, method, x_key, metric="relMSE"):
    """x values and (median, min, max) of `metric` over seeds, per x (grouped by budget).

    Against spp, a method run at spp budgets is plotted at those; one run only at time budgets
    (bsdf, whose time runs define the default spp budgets) at the median spp of each time budget."""
    groups = {}
    mine = [r for r in records if r["method"] == method]
    by_spp = x_key == "spp" and any(r["budget"] == "spp" for r in mine)
    for r in mine:
        if r["budget"] != ("spp" if by_spp else "time"):
            continue
        key = r["spp"] if by_spp else r["time_budget"]
        groups.setdefault(key, []).append(r)
    xs, med, lo, hi = [], [], [], []
    for key in sorted(groups):
        rs = groups[key]
        x = (key if by_spp else
             np.median([r["time_total"] if x_key == "time" else r["spp"] for r in rs]))
        e = [r["metrics"].get(metric, np.nan) for r in rs]
        xs.append(x), med.append(np.median(e)), lo.append(min(e)), hi.append(max(e))
    return np.array(xs), np.array(med), np.array(lo), np.array(hi)


def chart(records, scene, methods, x_key, path, floor=None):
    """One PNG: relMSE and 1-SSIM (CHART_METRICS) against wall time or spp, log-log, a line per
    method (median over seeds, band from min to max; denoised methods dashed), the reference's
    noise floor as a grey line on the relMSE panel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from matplotlib.ticker import NullFormatter, ScalarFormatter

    fig, axes = plt.subplots(1, len(CHART_METRICS), figsize=(10, 4.2), dpi=110)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    base = [m for m in methods if not m.endswith(DENOISED)]
    for ax, metric in zip(axes, CHART_METRICS):
        ticks = set()
        for m in methods:
            x, med, lo, hi = _band(records, m, x_key, metric)
            if len(x) == 0:
                continue
            # the budgets as ticks (a run's measured time is a little off its budget: 40 and 41)
            if x_key == "time":
                ticks.update(float(r["time_budget"]) for r in records if r["method"] == m and r["budget"] == "time")
            else:
                ticks.update(float(f"{v:.2g}") for v in x)
            raw = m[:-len(DENOISED)] if m.endswith(DENOISED) else m
            colour = colours[(base.index(raw) if raw in base else methods.index(m)) % len(colours)]
            ax.plot(x, med, marker="o", ms=3, label=m, color=colour, ls="--" if m.endswith(DENOISED) else "-")
            ax.fill_between(x, lo, hi, alpha=0.12, color=colour)
        if metric == "relMSE" and floor:
            ax.axhline(floor, color="grey", lw=1, ls=":", label="reference's noise floor")
        ax.set_xscale("log")
        if any(np.asarray(line.get_ydata(), float).max(initial=0.0) > 0 for line in ax.get_lines()):
            ax.set_yscale("log")
        if ticks:  # the budgets themselves as plain numbers, not crowded minor labels
            ax.set_xticks(sorted(ticks))
            ax.xaxis.set_major_formatter(ScalarFormatter())
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("wall time [s]" if x_key == "time" else "samples per pixel")
        ax.set_ylabel(metric)
        ax.set_title(f"{scene}: {metric} vs {'time' if x_key == 'time' else 'spp'}")
        ax.grid(True, which="both", alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="center right", fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0, 0.83, 1))
    atomic.write(path, fig.savefig)
    plt.close(fig)


def best_table(all_records, scenes, times):
    """Lines of the table on top of the summary: per scene and time budget, the method with the
    lowest mean relMSE and the one with the lowest mean 1-SSIM over seeds."""
    if not times:
        return []
    lines = ["Best method per scene and time budget (mean over seeds), by relMSE / by 1-SSIM:", "",
             "| scene | " + " | ".join(f"{t:g} s" for t in times) + " |", "|---|" + "---|" * len(times)]
    for scene in scenes:
        cells = []
        for t in times:
            recs = [r for r in all_records if r["scene"] == scene and r["budget"] == "time" and r["time_budget"] == t]
            best = []
            for metric in CHART_METRICS:
                means = {}
                for r in recs:
                    if r["metrics"].get(metric) is not None:
                        means.setdefault(r["method"], []).append(r["metrics"][metric])
                best.append(min(means, key=lambda m: np.mean(means[m])) if means else "-")
            cells.append(" / ".join(best))
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    return lines + [""]


def floor_check(records, floor):
    """(ok, smallest relMSE measured): a reference judges errors down to ten times its floor."""
    smallest = min(r["metrics"]["relMSE"] for r in records)
    return floor * 10.0 <= smallest, smallest


def update_seconds(r):
    """The guide's map rebuild between passes in record `r`; records made before `update_s` stored
    the same figure as `time_inference`. None if neither is there."""
    return r.get("update_s", r.get("time_inference"))


def shade_per_sample(r):
    """Seconds of the shade stage per camera sample of record `r`, None for records without them."""
    if r.get("shade_s") is None or not r.get("samples"):
        return None
    return r["shade_s"] / r["samples"]


def _median_of(rs, value):
    """Median over records `rs` of value(r); None when there are none or any lacks the value."""
    v = [value(r) for r in rs]
    return float(np.median(v)) if v and all(x is not None for x in v) else None


def shade_ns(recs, method, t):
    """Median over seeds of `method`'s shade seconds per sample at time budget `t`, in ns; None
    where there are no runs or they lack the figures."""
    v = _median_of([r for r in recs if r["method"] == method and r["budget"] == "time" and r["time_budget"] == t],
                   shade_per_sample)
    return None if v is None else v * 1e9


def shade_overhead_ns(recs, method, t):
    """What `method`'s shading costs over bsdf's at time budget `t`, in ns per sample: the median
    over seeds of its shade seconds per sample, minus bsdf's median. None where either is unknown."""
    mine, base = shade_ns(recs, method, t), shade_ns(recs, "bsdf", t)
    return None if mine is None or base is None else mine - base


def _cell(v, fmt):
    return "-" if v is None or not np.isfinite(v) else format(v, fmt)


def summary_table(all_records, scenes, methods, times, floors):
    lines = [f"# Convergence summary ({platform.machine()}, {os.cpu_count()} cores)", "",
             "Errors at equal wall time and at equal spp, mean over seeds; ratio to `bsdf` in brackets (< 1 is better).",
             "Reference check: its noise floor (expected relMSE of the reference itself) must be below a",
             "tenth of the smallest relMSE it judged.", ""] + best_table(all_records, scenes, times)
    for scene in scenes:
        ok, smallest = floor_check([r for r in all_records if r["scene"] == scene], floors[scene])
        recs = [r for r in all_records if r["scene"] == scene and r["budget"] == "time"]
        lines += [f"## {scene}", "",
                  f"Reference: noise floor {floors[scene]:.3g}, smallest error judged {smallest:.3g}: "
                  + ("good enough." if ok else "**too noisy: extend it with `bench.reference --append`**."), ""]
        for metric in (CHART_METRICS if times else ()):
            lines += [f"{metric} at equal time:", "",
                      "| method | " + " | ".join(f"{t:g} s" for t in times) + " |", "|---|" + "---|" * len(times)]
            lines += _rows(recs, methods, times, metric, "time_budget") + [""]
        base = {t: np.mean([r["metrics"]["relMSE"] for r in recs if r["method"] == "bsdf" and r["time_budget"] == t]
                           or [np.nan]) for t in times}
        lines += spp_table([r for r in all_records if r["scene"] == scene and r["budget"] == "spp"], methods)
        guided = [m for m in methods if m != "bsdf"] if times else []
        corrected = []
        for m in guided:
            cells = []
            for t in times:
                e = [r["metrics"]["relMSE"] for r in recs if r["method"] == m and r["time_budget"] == t]
                den = base[t] - floors[scene]
                cells.append(f"{(np.mean(e) - floors[scene]) / den:.2f}" if e and np.isfinite(den) and den > 0 else "-")
            corrected.append(f"{m} " + " / ".join(cells))
        if corrected:
            lines += ["Ratios to `bsdf` with the reference's noise floor taken off every relMSE (the reference's",
                      "error is independent of a render's, so each measured relMSE is about the true one plus the",
                      "floor): " + "; ".join(corrected) + ".", ""]
        if guided:
            lines += ["Guided shading's cost over `bsdf`'s: the shade stage's seconds per sample (median over",
                      "seeds) minus `bsdf`'s, in ns per sample; the `bsdf` row is its own (\"-\": not recorded).", "",
                      "| shade ns per sample | " + " | ".join(f"{t:g} s" for t in times) + " |",
                      "|---|" + "---|" * len(times),
                      "| bsdf | " + " | ".join(_cell(shade_ns(recs, "bsdf", t), ".0f") for t in times) + " |"]
            for m in guided:
                cells = [_cell(shade_overhead_ns(recs, m, t), "+.0f") for t in times]
                lines.append(f"| {m} | " + " | ".join(cells) + " |")
            lines.append("")
            lines += ["| method (at the largest time budget) | spp | learning s | update s | network inference s "
                      "| guide memory MB |",
                      "|---|---|---|---|---|---|"]
            for m in guided:
                rr = [r for r in recs if r["method"] == m and r["time_budget"] == max(times)]
                if rr:
                    lines.append(f"| {m} | {np.median([r['spp'] for r in rr]):.0f} | "
                                 f"{np.median([r['time_learning'] for r in rr]):.2f} | "
                                 f"{_cell(_median_of(rr, update_seconds), '.2f')} | "
                                 f"{_cell(_median_of(rr, lambda r: r.get('inference_s')), '.2f')} | "
                                 f"{max(r['guide_memory_bytes'] for r in rr) / 1e6:.0f} |")
            lines.append("")
    return "\n".join(lines)


def _rows(recs, methods, budgets, metric, key):
    """Table rows of `metric` at each budget (r[key] equal to it: "time_budget" or "spp"): mean over
    seeds, ratio to bsdf in brackets; "-" where a method has no run."""
    def values(m, x):
        return [r["metrics"][metric] for r in recs if r["method"] == m and r[key] == x
                and r["metrics"].get(metric) is not None]

    base = {x: np.mean(values("bsdf", x) or [np.nan]) for x in budgets}
    rows = []
    for m in methods:
        cells = []
        for x in budgets:
            e = values(m, x)
            if not e:
                cells.append("-")
                continue
            v = float(np.mean(e))
            cells.append(f"{v:.3g} ({v / base[x]:.2f})" if np.isfinite(base[x]) and base[x] > 0 else f"{v:.3g}")
        rows.append(f"| {m} | " + " | ".join(cells) + " |")
    return rows


SPP_METRICS = ("relMSE", "MrSE", "1-SSIM")  # MrSE: trimmed (the top 0.01% of pixel errors dropped)


def spp_table(recs, methods):
    """Lines of the equal-spp tables (relMSE, trimmed MrSE and 1-SSIM, mean over seeds, ratio to
    bsdf) and, for methods that record them, their guide statistics (medians over seeds); [] without
    spp records."""
    spps = sorted({r["spp"] for r in recs})
    if not spps:
        return []
    lines = []
    for metric in SPP_METRICS:
        lines += [f"{metric} at equal spp (every sample traced counts, a learning or initial pass's too):", "",
                  "| method | " + " | ".join(f"{n} spp" for n in spps) + " |", "|---|" + "---|" * len(spps)]
        lines += _rows(recs, methods, spps, metric, "spp") + [""]
    odis = [m for m in methods if any(r["method"] == m and r.get("guide_stats", {}).get("pixels_guided") is not None
                                      for r in recs)]
    if odis:
        lines += ["Initial-pass guides (medians over seeds): the share of pixels with a map, the gather window, the "
                  "share of valid bins the window filled, network inference seconds and their share of the render.",
                  "", "| method | spp | pixels with a map | window | bins filled | inference s | share of render |",
                  "|---|---|---|---|---|---|---|"]
        for m in odis:
            for n in spps:
                rr = [r for r in recs if r["method"] == m and r["spp"] == n]
                gs = [r["guide_stats"] for r in rr if r.get("guide_stats", {}).get("pixels_guided") is not None]
                if not gs:
                    continue
                share = np.median([g["pixels_guided"] / max(g["pixels"], 1) for g in gs])
                inf = np.median([r["inference_s"] for r in rr])
                frac = np.median([r["inference_s"] / r["time_total"] for r in rr])
                lines.append(f"| {m} | {n} | {share:.2f} | {gs[0]['window']} | "
                             f"{np.median([g['centre_sparsity'] for g in gs]):.2f} | {inf:.3f} | {frac:.1%} |")
        lines.append("")
    keyed = [m for m in methods if any(r["method"] == m and r.get("guide_stats", {}).get("zero_share_uniform")
                                       is not None for r in recs)]
    if keyed:
        lines += [f"At {spps[-1]} spp (medians over seeds): the model chosen (m bounces, coupling layers x width), "
                  "validation NLL, the share of zero-valued samples in the uniform candidate pass and in the warped "
                  "passes, the per-sample second moment the warp promises against uniform sampling (validation "
                  "candidates), learning seconds, inference microseconds per sample.", "",
                  "| method | model | val NLL | zero share uniform | zero share warped | second moment ratio "
                  "| learning s | inference us/sample |", "|---|---|---|---|---|---|---|---|"]
        for m in keyed:
            rr = [r for r in recs if r["method"] == m and r["spp"] == spps[-1]]
            gs = [r["guide_stats"] for r in rr]
            models = sorted({f"m{g['m']} {g['layers']}x{g['width']}" if g.get("m") else "uniform" for g in gs})

            def med(key):
                v = [g[key] for g in gs if g.get(key) is not None]
                return float(np.median(v)) if v else np.nan
            lines.append(f"| {m} | {', '.join(models)} | {med('val_nll'):.2f} | {med('zero_share_uniform'):.3f} | "
                         f"{med('zero_share_final'):.3f} | {med('second_moment_ratio'):.2f} | "
                         f"{np.median([r['time_learning'] for r in rr]):.1f} | {med('inference_us_per_sample'):.2f} |")
        lines.append("")
    return lines


def write_outputs(out, all_records, scenes, methods, times, floors):
    """records.jsonl, the two charts per scene and summary.md in `out`; returns the summary."""
    atomic.write_jsonl(os.path.join(out, "records.jsonl"), all_records)
    for name in scenes:
        recs = [r for r in all_records if r["scene"] == name]
        chart(recs, name, methods, "time", os.path.join(out, f"{name}_time.png"), floors.get(name))
        chart(recs, name, methods, "spp", os.path.join(out, f"{name}_spp.png"), floors.get(name))
    table = summary_table(all_records, scenes, methods, times, floors)
    atomic.write_text(os.path.join(out, "summary.md"), table + "\n")
    return table


def rescore(out, scene_dir=None):
    """Score the stored images of a run again against the references as they are now."""
    with open(os.path.join(out, "records.jsonl")) as f:
        records = [json.loads(line) for line in f if line.strip()]
    if not records:
        raise SystemExit(f"bench.convergence: {out}/records.jsonl holds no records")
    scenes = list(dict.fromkeys(r["scene"] for r in records))
    methods = list(dict.fromkeys(r["method"] for r in records))
    times = sorted({r["time_budget"] for r in records if r["budget"] == "time"})
    floors = {}
    for name in scenes:
        given = next(r.get("scene_path") for r in records if r["scene"] == name)
        ref, _, meta = reference_for(os.path.join(ROOT, given) if given else scene_path(name, scene_dir))
        floors[name] = meta["noise_floor_relmse"]
        for r in records:
            if r["scene"] != name:
                continue
            if not r.get("image"):
                raise SystemExit(f"bench.convergence: a record of {name} in {out} has no stored image")
            image = np.load(os.path.join(out, "images", name, r["image"]))
            r["metrics"] = metrics.all_metrics(image, ref)
    return write_outputs(out, records, scenes, methods, times, floors)


def cell_key(c):
    """What identifies a cell, and the record it makes: scene, method, seed, budget."""
    return (c["scene"], c["method"], c["seed"], c["budget"],
            float(c["time_budget"]) if c["budget"] == "time" else int(c["spp"]))


_LOADED = {}  # in each worker process: scene path -> (scene, reference), loaded and warmed up once


def run_cell(cell):
    """One cell in a worker: its record (run_one's, with scene and provenance)."""
    path, key = cell["path"], (cell["path"], cell["ref_dir"])
    if key not in _LOADED:
        ref, _, meta = load_reference(cell["ref_dir"])
        scene = tracer.load_scene(path, width=meta["width"], height=meta["height"])  # the reference's size
        tracer.render(scene, spp=1, threads=cell["threads"])  # compile and warm up outside every budget
        _LOADED[key] = scene, ref
    scene, ref = _LOADED[key]
    r = run_one(scene, cell["method"], cell["seed"], ref, time_budget=cell["time_budget"],
                spp=None if cell["budget"] == "time" else cell["spp"], images=cell["images"], threads=cell["threads"])
    r.update(scene=cell["scene"], scene_path=os.path.relpath(path, ROOT),
             machine=f"{platform.machine()}, {os.cpu_count()} cores", date=time.strftime("%Y-%m-%d %H:%M"),
             threads=cell["threads"])
    if hasattr(os, "sched_getaffinity"):
        r["cores"] = sorted(os.sched_getaffinity(0))  # the cores the render's threads could run on
    gc.collect()  # a worker renders hundreds of times: what a cycle holds goes now, not at the next full collection
    if cell["budget"] == "spp":
        r["spp_budget"] = cell["spp"]
    return r


def read_records(out):
    """The records stored in out/records.jsonl ([] if none)."""
    path = os.path.join(out, "records.jsonl")
    if not os.path.isfile(path):
        return []
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def record_key(r):
    """cell_key of the cell that made record `r`."""
    return cell_key(dict(r, spp=r.get("spp_budget", r["spp"])))


def default_spps(records, scene, times):
    """bsdf's median spp at each time budget on `scene`: the default spp budgets."""
    out = set()
    for t in times:
        v = [r["spp"] for r in records if r["scene"] == scene and r["method"] == "bsdf" and r["budget"] == "time"
             and r["time_budget"] == t]
        if v:
            out.add(int(np.median(v)))
    return sorted(out)


def sweep(out, scenes, methods, times, spps, seeds, threads, scheduler=None, workers=None, fresh=False,
          progress=True):
    """Every cell (scene x method x seed x budget) not yet in out/records.jsonl, on Dask
    (bench.sweep); each record is added to the file as it arrives. scenes: [(name, path)]; spps
    None: bsdf's spp at each time budget (then bsdf is not run again at them), [] none. Returns
    all records (the stored ones first)."""
    os.makedirs(out, exist_ok=True)
    log = os.path.join(out, "records.jsonl")
    records = [] if fresh else read_records(out)
    kept = len(records)

    def done(cell, r):
        records.append(r)
        atomic.write_jsonl(log, records)  # after every cell, whole: a killed sweep keeps what finished
        if progress:
            print(f"{r['scene']} {r['method']} seed {r['seed']} {r['budget']} "
                  f"{r['time_budget'] if r['budget'] == 'time' else r['spp']}: {r['spp']} spp, "
                  f"relMSE {r['metrics']['relMSE']:.4g}", flush=True)

    def cell(name, path, m, seed, budget, value):
        return {"scene": name, "path": path, "ref_dir": common.default_out(path), "method": m, "seed": seed,
                "budget": budget, "threads": threads,
                "time_budget": value if budget == "time" else None, "spp": value if budget == "spp" else None,
                "images": os.path.join(out, "images", name)}

    # methods interleaved, so that a drift of the machine's speed touches them alike
    timed = [cell(n, p, m, s, "time", t) for n, p in scenes for s in range(seeds) for t in times for m in methods]
    new = sweep_module.todo(timed, records, record_key)
    if kept and progress:
        print(f"bench.convergence: {kept} records in {log} kept, {len(timed) - len(new)} of "
              f"{len(timed)} time cells done", flush=True)
    sweep_module.run(run_cell, new, done, threads=threads, scheduler=scheduler, workers=workers,
                     progress=progress, desc="time cells")
    counted = []
    for n, p in scenes:
        ns = default_spps(records, n, times) if spps is None else spps
        for m in (methods if spps is not None else [m for m in methods if m != "bsdf"]):
            counted += [cell(n, p, m, s, "spp", k) for s in range(seeds) for k in ns]
    sweep_module.run(run_cell, sweep_module.todo(counted, records, record_key), done, threads=threads,
                     scheduler=scheduler, workers=workers, progress=progress, desc="spp cells")
    return records


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.convergence", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", help="comma-separated scene names or paths")
    p.add_argument("--methods", default="bsdf", help="comma-separated registered guide names, each with "
                   "optional settings: name:key=value,... (separate methods with ';' when settings are given); "
                   "`all`: ALL_METHODS; any method with +oidn after it is denoised")
    p.add_argument("--time", default="10,20,40,80", help="comma-separated wall-time budgets in seconds "
                   "(none: spp budgets only, given by --spp)")
    p.add_argument("--spp", default=None, help="comma-separated spp budgets (default: what bsdf reached; none: time budgets only)")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--scene-dir", default=None, help="folder of external scenes (<dir>/<name>/scene.obj "
                   "or scene.xml)")
    p.add_argument("--out", default=DEFAULT_OUT)
    p.add_argument("--threads", type=int, default=os.cpu_count() or 1,
                   help="threads of each render (default: all cores); the LocalCluster runs cores // threads at once")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a Dask scheduler to run the cells on (default: a LocalCluster on this machine)")
    p.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: cores // threads; "
                   "0: no Dask, every cell in this process)")
    p.add_argument("--fresh", action="store_true", help="ignore the records already in --out (default: "
                   "keep them and run only the cells they lack, so a stopped sweep resumes)")
    p.add_argument("--rescore", action="store_true", help="render nothing: score the run stored in --out "
                   "again against the current references")
    a = p.parse_args(argv)
    if a.rescore:
        print(rescore(a.out, a.scene_dir))
        return 0
    if not a.scenes:
        p.error("--scenes is required (unless --rescore)")
    if a.threads < 1:
        p.error("--threads must be >= 1")
    spec = ";".join(ALL_METHODS) if a.methods == "all" else a.methods
    methods = [m.strip() for m in spec.split(";" if ";" in spec else ",") if m.strip()]
    for m in methods:  # an unknown guide or setting fails now, not after an hour of runs
        check_method(m)
    if "bsdf" not in methods:
        methods.insert(0, "bsdf")  # every ratio is against bsdf
    times = [] if a.time == "none" else [float(t) for t in a.time.split(",")]
    if not times and (a.spp is None or a.spp == "none"):
        p.error("--time none needs --spp budgets")
    spps = None if a.spp is None else [] if a.spp == "none" else [int(s) for s in a.spp.split(",")]
    scenes, floors = [], {}
    for given in (s.strip() for s in a.scenes.split(",") if s.strip()):
        path = os.path.abspath(scene_path(given, a.scene_dir))
        name = scene_name(given)
        floors[name] = reference_for(path)[2]["noise_floor_relmse"]  # a missing reference fails now
        scenes.append((name, path))
    records = sweep(a.out, scenes, methods, times, spps, a.seeds, a.threads, a.scheduler, a.workers, a.fresh)
    names = [n for n, _ in scenes]  # records.jsonl keeps every scene's records; the summary is of these
    print(write_outputs(a.out, records, names, methods, times, floors))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
