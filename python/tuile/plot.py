"""tuile's pictures, drawn by matplotlib: error against time and contact sheets.

    import tuile, tuile.plot
    rows = tuile.converge(scene, strategies=["bsdf", "mis:power"], budget=2)
    ax = tuile.plot.error_vs_time(rows)              # log-log, one line per strategy
    fig = tuile.plot.contact_sheet({"MIS": image})   # images side by side, sRGB

The command line draws through this file too: `tuile converge --plot` and `tuile figures`
write their data (JSON, .npy images) and run `python3 plot.py SPEC.json`. This file needs
only numpy and matplotlib (not the compiled module), so it also runs as that script.
"""
import json
import sys

import numpy as np

__all__ = ["srgb", "error_vs_time", "series_vs_time", "contact_sheet", "figure_for"]


def srgb(image):
    """Linear RGB to sRGB-encoded values in [0, 1] (the display transform of tuile's PNGs)."""
    x = np.clip(np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _display(image, display):
    a = np.asarray(image, dtype=np.float64)
    if display == "srgb":
        return srgb(a), None
    if display == "grey":  # a [0, 1] quantity, linearly
        if a.ndim == 3:
            a = a[..., 0]
        return np.clip(np.nan_to_num(a), 0, 1), "gray"
    if display == "signed":  # luminance: positive as sRGB grey, negative in red
        y = 0.2126 * a[..., 0] + 0.7152 * a[..., 1] + 0.0722 * a[..., 2]
        v = srgb(np.abs(y))
        neg = y < 0
        return np.stack([v, np.where(neg, 0, v), np.where(neg, 0, v)], axis=-1), None
    raise ValueError("display: expected srgb, grey or signed, not %r" % (display,))


def _guide(ax, xs, ys, slope, label):
    """A dashed line of the given log-log slope through the data's geometric middle."""
    x = np.asarray([v for v in xs if v and v > 0 and np.isfinite(v)], dtype=np.float64)
    y = np.asarray([v for v in ys if v and v > 0 and np.isfinite(v)], dtype=np.float64)
    if len(x) < 2 or len(y) < 2:
        return
    lx = np.log(x)
    x0, x1 = x.min(), x.max()
    cx, cy = np.exp(lx.mean()), np.exp(np.log(y).mean())
    gx = np.array([x0, x1])
    ax.plot(gx, cy * (gx / cx) ** slope, linestyle="--", color="0.5", linewidth=1, label=label)


def series_vs_time(series, ax=None, title=None, xlabel="render time (s)", ylabel="relMSE", guide_slope=-1.0,
                   guide_label="1/t"):
    """Log-log lines, one per series: series is a list of (name, xs, ys). A dashed guide of
    slope guide_slope (None: none). Returns the axes."""
    import matplotlib.pyplot as plt
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 4.8))
    all_x, all_y = [], []
    for name, xs, ys in series:
        xs = [np.nan if v is None else v for v in xs]
        ys = [np.nan if v is None else v for v in ys]
        ax.plot(xs, ys, marker="o", markersize=3.5, linewidth=1.5, label=name)
        all_x += xs
        all_y += ys
    if guide_slope:
        _guide(ax, all_x, all_y, guide_slope, guide_label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(True, which="major", linewidth=0.6, alpha=0.5)
    ax.grid(True, which="minor", linewidth=0.3, alpha=0.3)
    ax.legend(fontsize="small", loc="best")
    return ax


def error_vs_time(rows, ax=None, metric="relmse", title=None, guide=True):
    """Error against time from tuile.converge's rows (or `tuile converge --csv` read with
    csv.DictReader): one line per strategy, in the rows' order, log-log, with a slope -1
    guide (error proportional to 1/t). Returns the axes."""
    order, by = [], {}
    for r in rows:
        name = r["strategy"]
        if name not in by:
            by[name] = ([], [])
            order.append(name)
        by[name][0].append(float(r["seconds"]))
        by[name][1].append(float(r[metric]))
    return series_vs_time([(n, by[n][0], by[n][1]) for n in order], ax=ax, title=title,
                          ylabel={"relmse": "relMSE", "mse": "MSE"}.get(metric, metric),
                          guide_slope=-1.0 if guide else None)


def contact_sheet(images, labels=None, title=None, columns=3, display="srgb", scale=1.0):
    """Images side by side, each under its label, in rows of at most `columns`: images is a
    dict {label: array} or a list (then labels). display: "srgb" (linear RGB), "grey" (a
    [0, 1] quantity such as an MIS weight), "signed" (negative luminance in red), or a
    list, one per image. Each image is shown at its pixel size times `scale` (at least 2.4
    inches wide). Returns the figure."""
    import matplotlib.pyplot as plt
    if isinstance(images, dict):
        labels = list(images.keys())
        images = list(images.values())
    images = [np.asarray(i) for i in images]
    if not images:
        raise ValueError("contact_sheet: no images")
    labels = list(labels) if labels is not None else [""] * len(images)
    displays = list(display) if isinstance(display, (list, tuple)) else [display] * len(images)
    columns = max(1, min(int(columns), len(images)))
    rows = (len(images) + columns - 1) // columns
    h = max(i.shape[0] for i in images)
    w = max(i.shape[1] for i in images)
    dpi = 100
    cell_w = max(w * scale / dpi, 2.4)
    cell_h = cell_w * h / w
    fig, axes = plt.subplots(rows, columns, figsize=(columns * cell_w, rows * (cell_h + 0.35) + (0.45 if title else 0.1)),
                             squeeze=False, dpi=dpi)
    for k, ax in enumerate(axes.flat):
        ax.set_axis_off()
        if k >= len(images):
            continue
        shown, cmap = _display(images[k], displays[k])
        ax.imshow(shown, cmap=cmap, vmin=0, vmax=1, interpolation="nearest")
        ax.set_title(labels[k], fontsize=9)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def figure_for(rows, images, title=None):
    """tuile.converge's rows and images in one figure: error against time on the left,
    each strategy's last image beside it (the README's example figure)."""
    import matplotlib.pyplot as plt
    names = [n for n in images if n != "reference"]
    fig = plt.figure(figsize=(4.2 + 2.6 * len(names), 3.6))
    grid = fig.add_gridspec(1, 1 + len(names), width_ratios=[1.6] + [1] * len(names))
    error_vs_time(rows, ax=fig.add_subplot(grid[0, 0]))
    for k, n in enumerate(names):
        ax = fig.add_subplot(grid[0, k + 1])
        ax.imshow(srgb(images[n]), interpolation="nearest")
        ax.set_title(n, fontsize=9)
        ax.set_axis_off()
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def main(argv):
    """python3 plot.py SPEC.json: the figures of `tuile converge --plot` and `tuile figures`."""
    if len(argv) != 2:
        print("usage: plot.py SPEC.json (written by tuile converge --plot, tuile figures)", file=sys.stderr)
        return 2
    import matplotlib
    matplotlib.use("Agg")
    matplotlib.rcParams["svg.fonttype"] = "none"  # text stays text in SVG files
    import matplotlib.pyplot as plt
    with open(argv[1]) as f:
        spec = json.load(f)
    for p in spec.get("plots", []):
        ax = series_vs_time([(s["name"], s["x"], s["y"]) for s in p["series"]], title=p.get("title"),
                            xlabel=p.get("xlabel", ""), ylabel=p.get("ylabel", ""),
                            guide_slope=p.get("guide_slope") or None, guide_label=p.get("guide_label", ""))
        ax.figure.tight_layout()
        ax.figure.savefig(p["output"], dpi=120)
        plt.close(ax.figure)
    for s in spec.get("sheets", []):
        panels = s["panels"]
        fig = contact_sheet([np.load(p["file"]) for p in panels], [p["label"] for p in panels], title=s.get("title"),
                            columns=s.get("columns", 3), display=[p.get("display", "srgb") for p in panels])
        fig.savefig(s["output"])
        plt.close(fig)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
