"""The bench's plots (matplotlib: the ``plot`` extra)."""
from __future__ import annotations


def check_plot_path(path: str) -> None:
    """Refuse, before a bench runs, a --plot file matplotlib cannot write (its extension names
    no format it has, or matplotlib is missing)."""
    import os

    from clfx.core.errors import ClfxError

    try:
        from matplotlib.backend_bases import FigureCanvasBase
    except ImportError as exc:
        raise ClfxError("--plot needs matplotlib: pip install 'clfx[plot]'") from exc
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    kinds = FigureCanvasBase.get_supported_filetypes()
    if ext not in kinds:
        raise ClfxError(f"--plot {path}: {('.' + ext) if ext else 'no extension'} is not a "
                        f"format matplotlib writes; expected one of "
                        f"{', '.join('.' + k for k in sorted(kinds))}")


def pareto_plot(results: dict, path: str) -> None:
    """Time vs relative error, one line per effect (needs matplotlib: the [plot] extra)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        from clfx.core.errors import ClfxError

        raise ClfxError("--plot needs matplotlib: pip install 'clfx[plot]'") from exc
    fig, ax = plt.subplots(figsize=(8, 5.5))
    styles = [(ls, m) for ls in ("-", "--", ":") for m in ("o", "s", "^", "D", "v", "P")]
    for i, e in enumerate(results["effects"]):
        # error 0 (a level identical to the reference, or the reference itself) has no place
        # on a log axis: such points are left out
        pts = [(r["ms"], r["rel_rmse"]) for r in e["rows"]
               if not r.get("identity") and r["rel_rmse"] > 0]
        if pts:
            xs, ys = zip(*pts)
            ls, m = styles[i % len(styles)]
            ax.plot(xs, ys, linestyle=ls, marker=m, label=e["effect"])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time per frame (ms)")
    ax.set_ylabel("relative RMSE vs reference level / ground truth\n(levels with error 0 not shown)")
    ax.set_title(f"clfx: what accuracy costs ({results['size'][0]}x{results['size'][1]})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
