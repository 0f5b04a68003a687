"""A design of the next measurements (:func:`skinfit.analysis.design.design`, a folder of
``skinfit design --out``) as a section of the HTML report: its figure and its tables as cells
(:func:`skinfit.report.tables.cells`), at the precision their Monte Carlo errors allow."""

from pathlib import Path

from skinfit.errors import InputError
from skinfit.io.labels import round_to_sd
from skinfit.io.models import load_model
from skinfit.plots.design import plot_eig
from skinfit.report.tables import cells, shown_unit, unit_or_dash

__all__ = ["design_section"]


def _parameter_units(model_id):
    """({parameter: display unit}, {parameter: SI unit}) from the design's model card; empty
    when the card cannot be read here (a model built from a function in another session)."""
    try:
        model = load_model(model_id)
    except (InputError, OSError):
        return {}, {}
    return ({p.name: p.display_unit for p in model.parameters if p.display_unit},
            {p.name: p.unit for p in model.parameters})


def _sd_table(result):
    """Predicted posterior sd per target parameter, with its unit: an sd of the natural log
    (``log`` coordinate) is a relative sd, without unit; a ``natural`` one is in the card's
    display unit where it names one (values converted), else in its SI unit. Each sd to two
    significant digits (an sd's own precision), the plan/baseline ratio to two decimals."""
    display, si_units = _parameter_units(result.model_id)
    table = result.sd.astype(object).copy()
    sds = ["now", "plan", "baseline"]
    units = []
    for name, coordinate in zip(table.index, table["coordinate"]):
        factor, unit = (1.0, "- (sd of ln)") if coordinate == "log" else shown_unit(name, display, si_units)
        units.append(unit if coordinate == "log" else unit_or_dash(unit))
        for c in sds:
            value = float(result.sd.loc[name, c]) / factor
            table.loc[name, c] = round_to_sd(value, value)
        table.loc[name, "plan/baseline"] = f"{float(result.sd.loc[name, 'plan/baseline']):.2f}"
    table.insert(list(table.columns).index("coordinate") + 1, "unit", units)
    return cells(table, "parameter")


def design_section(result, figdir):
    """The report's section on a design (a dict for the page's template): its id and heading, a
    sentence on how it was made, the EIG figure (written to ``figdir/design_<model>.png``), and
    tables of plan vs baseline (EIG in nats, nested Monte Carlo ± its standard error), the
    predicted posterior sd (with units), the discrimination between models when asked for, and
    the plan in the user's units."""
    figdir = Path(figdir)
    figdir.mkdir(parents=True, exist_ok=True)
    name = f"design_{result.model_id}.png"
    plot_eig(result, figdir / name)
    s = result.settings
    sentence = (f"{len(result.plan)} measurements chosen from {s['candidates']} candidates by {s['selection']}, "
                f"starting from {s['start']}; targets {', '.join(s['params'])}; seed {s['seed']}. Baseline: "
                f"{s['baseline']}. Single-candidate EIG: {s['eig_single']}; batch EIG: {s['eig_batch']}. "
                f"Laplace values are {s['laplace']}.")
    comparison = result.comparison.rename(columns={"eig_nmc": "eig", "eig_nmc_se": "eig_se",
                                                   "eig_nmc_bias": "eig_bias"})
    if "eig_bias" in comparison:  # a Monte Carlo estimate of the bias: at the precision of the EIG's error
        comparison["eig_bias"] = [round_to_sd(b, se) for b, se in zip(comparison["eig_bias"], comparison["eig_se"])]
    tables = [{"title": "Plan vs baseline: expected information gain of the whole batch [nats]",
               "kind": "design-comparison", "table": cells(comparison, "measurements")},
              {"title": "Predicted posterior sd, now, after the plan and after the baseline",
               "kind": "design-sd", "table": _sd_table(result)}]
    if result.discrimination is not None:
        d = result.discrimination
        tables.append({"title": "Discrimination", "kind": "design-discrimination",
                       "table": cells(d.set_index(d.columns[0]), str(d.columns[0]))})
    plan = result.plan
    tables.append({"title": "Plan (user units)", "kind": "design-plan",
                   "table": cells(plan.set_index(plan.columns[0]), str(plan.columns[0]))})
    return {"id": f"design-{result.model_id}", "name": result.model_id, "sentence": sentence,
            "figure": {"file": f"{figdir.name}/{name}", "alt": "expected information gain over the candidates"},
            "tables": tables}
