"""A design of the next measurements (:func:`skinfit.analysis.design.design`, a folder of
``skinfit design --out``) as a section of the HTML report."""

import html
from pathlib import Path

from skinfit.plots.design import plot_eig

__all__ = ["design_section_html"]


def design_section_html(result, figdir):
    """A self-contained HTML section (string) for a report: the EIG figure (written to
    ``figdir/design_<model>.png``), plan vs baseline, predicted sds and the plan."""
    figdir = Path(figdir)
    figdir.mkdir(parents=True, exist_ok=True)
    name = f"design_{result.model_id}.png"
    plot_eig(result, figdir / name)
    s = result.settings
    parts = [f"<section id=\"design-{html.escape(result.model_id)}\"><h2>Design the next experiment: "
             f"{html.escape(result.model_id)}</h2>",
             f"<p>{len(result.plan)} measurements chosen from {s['candidates']} candidates by "
             f"{html.escape(s['selection'])}, starting from {html.escape(s['start'])}; targets "
             f"{html.escape(', '.join(s['params']))}; seed {s['seed']}. Baseline: {html.escape(s['baseline'])}. "
             f"Single-candidate EIG: {html.escape(s['eig_single'])}; batch EIG: {html.escape(s['eig_batch'])}. "
             f"Laplace values are {html.escape(s['laplace'])}.</p>",
             f"<img src=\"{html.escape(figdir.name)}/{name}\" alt=\"expected information gain over the candidates\">",
             "<h3>Plan vs baseline</h3>", result.comparison.to_html(float_format=lambda v: f"{v:.3g}"),
             "<h3>Predicted posterior sd</h3>", result.sd.to_html(float_format=lambda v: f"{v:.3g}")]
    if result.discrimination is not None:
        parts += ["<h3>Discrimination</h3>",
                  result.discrimination.to_html(index=False, float_format=lambda v: f"{v:.3g}")]
    parts += ["<h3>Plan (user units)</h3>", result.plan.to_html(index=False, float_format=lambda v: f"{v:.4g}"),
              "</section>"]
    return "\n".join(parts)
