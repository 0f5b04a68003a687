"""One trial of ``skinfit ingest``: its traces, the filtered signals, the strokes found, the
kept windows shaded and the dropped ones marked with their reason, so a person can check the
segmentation before fitting (the ``--review`` page)."""

from skinfit.plots.style import COLOURS, finish_figure, new_figure, suptitle

__all__ = ["plot_trial"]

_KEPT, _DROPPED = "#009E73", "#D55E00"


def plot_trial(record, rig, path=None):
    """Figure of one trial's record (:class:`skinfit.io.recordings.ingest.TrialRecord` with
    ``traces``): a panel per signal (raw in grey, filtered in colour, SI units) and the velocity
    with its threshold; kept windows shaded green, dropped strokes red with their reason."""
    traces = record.traces
    names = [k for k in traces if k != "t" and not k.startswith("raw:")]
    names = [rig.normal] + [n for n in names if n not in (rig.normal, "velocity", rig.position)] + ["velocity"]
    fig = new_figure(9.0, 1.6 * len(names) + 0.8)
    axes = fig.subplots(len(names), 1, sharex=True, squeeze=False)[:, 0]
    t = traces["t"]
    units = {**{k: u for k, (_, u) in rig.derived.items()}, "velocity": "m/s"}
    for ax, name, colour in zip(axes, names, COLOURS):
        if "raw:" + name in traces:
            ax.plot(t, traces["raw:" + name], color="#BBBBBB", lw=0.5, label="raw (calibrated)")
        ax.plot(t, traces[name], color=colour, lw=0.8, label="filtered")
        ax.set_ylabel(f"{name}\n[{units.get(name, '')}]", fontsize=8)
        for s in record.strokes:
            a, b = s["kept_start"] / record.rate, s["kept_stop"] / record.rate
            if s["reason"]:
                ax.axvspan(s["start"] / record.rate, s["stop"] / record.rate, color=_DROPPED, alpha=0.15, lw=0)
            else:
                ax.axvspan(a, b, color=_KEPT, alpha=0.2, lw=0)
    axes[0].axhline(rig.normal_force_above, color="k", ls=":", lw=0.8)
    axes[-1].axhline(rig.speed_above, color="k", ls=":", lw=0.8)
    axes[-1].axhline(-rig.speed_above, color="k", ls=":", lw=0.8)
    axes[0].legend(loc="upper right", fontsize=8, frameon=False)
    for i, s in enumerate(record.strokes):
        if s["reason"]:
            axes[0].annotate(f"dropped {i + 1}", (s["start"] / record.rate, 1.0), xycoords=("data", "axes fraction"),
                             fontsize=8, color=_DROPPED, va="bottom")
    axes[-1].set_xlabel("time [s]")
    status = "kept" if record.kept else f"REJECTED: {record.reason}"
    kept = sum(not s["reason"] for s in record.strokes)
    suptitle(fig, f"{record.name}: {len(record.strokes)} strokes found, {kept} kept (green), "
             f"{len(record.strokes) - kept} dropped (red); trial {status}")
    return finish_figure(fig, path)
