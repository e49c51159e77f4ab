"""A campaign's outputs: trials.csv (a row per trial), summary.json (success rate, its
Wilson 95 % interval, counts per failure class) and plots of success against each drawn
parameter. Pure but for the files it writes; matplotlib is imported only to plot.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

from simulator.verdict import FAILURE_CLASSES

Z95 = 1.959963984540054  # standard normal quantile of 0.975


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (Wilson, JASA 22:209-212, 1927):
    (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n), p = successes / n."""
    if n <= 0:
        return (0.0, 1.0)
    p = successes / n
    d = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / d
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4 * n * n)) / d
    # the interval contains p exactly: the bounds' round-off must not put p outside it
    return (min(p, max(0.0, centre - half)), max(p, min(1.0, centre + half)))


def add_derived(rows: list[dict]) -> None:
    """Per-AM draws folded into one column each (the worst AM): |misalignment|, |start offset|."""
    for r in rows:
        mis = [abs(v) for k, v in r.items() if k.endswith("_misalignment_deg")]
        if mis:
            r["max_abs_misalignment_deg"] = max(mis)
        offs = {}
        for k, v in r.items():
            if "_start_offset_" in k:
                offs.setdefault(k.split("_start_offset_")[0], []).append(v)
        if offs:
            r["max_start_offset_m"] = max(math.sqrt(sum(x * x for x in o)) for o in offs.values())


def summarize(rows: list[dict], **context) -> dict:
    """Success over all trials and over the flown ones: a trial the pre-flight check refused
    (verdict "refused", outside the team's envelope) never flew, so it is neither a success nor
    a failure of flight; it counts in `refused` and in the rate over all trials."""
    n = len(rows)
    ok = sum(r["verdict"] == "success" for r in rows)
    refused = sum(r["verdict"] == "refused" for r in rows)
    flown = n - refused
    lo, hi = wilson_interval(ok, n)
    classes = {c: sum(r["failure_class"] == c for r in rows) for c in FAILURE_CLASSES}
    return {**context, "trials": n, "successes": ok, "success_rate": ok / n if n else None,
            "wilson95": [lo, hi], "failure_classes": classes,
            "incomplete": sum(r["verdict"] == "incomplete" for r in rows),
            "refused": refused, "flown": flown, "success_rate_flown": ok / flown if flown else None,
            "wilson95_flown": list(wilson_interval(ok, flown))}


def summary_line(s: dict) -> str:
    """The campaign's result in one sentence (am-trials prints it)."""
    def rate(k: int, n: int, bounds) -> str:
        return (f"{k}/{n} succeeded ({100 * k / n:.0f} %, Wilson 95 % {100 * bounds[0]:.0f}-{100 * bounds[1]:.0f} %)"
                if n else "none flown")

    failed = ", ".join(f"{c} {n}" for c, n in s["failure_classes"].items() if n)
    tail = f"; failures: {failed}" if failed else ""
    if s.get("incomplete"):  # cut short before the hover window ended: neither success nor failure
        tail += f"; incomplete {s['incomplete']} (the run ended before the hover window did)"
    if not s.get("refused"):
        return rate(s["successes"], s["trials"], s["wilson95"]) + tail
    return (f"{s['refused']} of {s['trials']} refused before flight (outside the team's envelope); of the "
            f"{s['flown']} flown, " + rate(s["successes"], s["flown"], s["wilson95_flown"])
            + tail + "; over all trials " + rate(s["successes"], s["trials"], s["wilson95"]))


def write_csv(rows: list[dict], path: Path) -> None:
    fields: list[str] = []
    for r in rows:
        fields += [k for k in r if k not in fields]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        for r in rows:
            w.writerow({k: _cell(v) for k, v in r.items()})


def _cell(v):
    return repr(v) if isinstance(v, float) else v


def read_csv(path: Path) -> list[dict]:
    """trials.csv back as rows (numbers as numbers)."""
    with open(path, newline="") as fh:
        return [{k: _parse(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def _parse(v: str):
    for cast in (int, float):
        try:
            return cast(v)
        except ValueError:
            pass
    return v


def write_summary(summary: dict, path: Path) -> None:
    path.write_text(json.dumps(summary, indent=1) + "\n")


def plot_parameters(rows: list[dict], params: list[str], out_dir: Path, title: str, bins: int = 5) -> list[Path]:
    """For each drawn parameter, success (1) or failure (0) of every trial against it, and the
    success rate with its Wilson interval in `bins` equal-count bins. One PNG each."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    if not rows:
        return paths
    ok = np.array([r["verdict"] == "success" for r in rows], dtype=float)
    for name in params:
        x = np.array([float(r[name]) for r in rows])
        if np.ptp(x) == 0.0:
            continue
        fig, ax = plt.subplots(figsize=(5.5, 3.4))
        jitter = np.random.default_rng(0).uniform(-0.03, 0.03, len(x))  # for display only
        ax.scatter(x, ok + jitter, s=9, c=np.where(ok > 0, "tab:green", "tab:red"), alpha=0.6, label="trials")
        order = np.argsort(x)
        for chunk in np.array_split(order, min(bins, len(x))):
            if not len(chunk):
                continue
            k, n = int(ok[chunk].sum()), len(chunk)
            lo, hi = wilson_interval(k, n)
            xm = float(x[chunk].mean())
            ax.errorbar(xm, k / n, yerr=[[k / n - lo], [hi - k / n]], fmt="o", color="k", capsize=3)
        ax.set_ylim(-0.1, 1.1)
        ax.set_xlabel(name)
        ax.set_ylabel("success (rate, Wilson 95 %)")
        ax.set_title(title, fontsize=9)
        fig.tight_layout()
        p = out_dir / f"success_vs_{name}.png"
        fig.savefig(p, dpi=90)
        plt.close(fig)
        paths.append(p)
    return paths


def comparison_table(summaries: list[dict]) -> str:
    """A Markdown table of several campaigns' summaries (one row per controller)."""
    head = ("| controller | trials | success | Wilson 95 % | refused | incomplete | " + " | ".join(FAILURE_CLASSES)
            + " |")
    rule = "|---" * (6 + len(FAILURE_CLASSES)) + "|"
    lines = [head, rule]
    for s in summaries:
        lo, hi = s["wilson95"]
        lines.append(f"| {s.get('controller', '?')} | {s['trials']} | {100 * s['success_rate']:.0f} % | "
                     f"{100 * lo:.0f}-{100 * hi:.0f} % | {s.get('refused', 0)} | {s.get('incomplete', 0)} | "
                     + " | ".join(str(s["failure_classes"][c]) for c in FAILURE_CLASSES) + " |")
    return "\n".join(lines) + "\n"
