"""What a command may replace in the folder it writes into: its own earlier results, and only
when asked (``--overwrite``).

``skinfit fit`` (single and ``--by``) checks its folder with :func:`skinfit.analysis.groups.check_out_dir`;
``skinfit population``, ``skinfit design`` and ``skinfit sbc`` with :func:`check_outputs`, before
any work starts. ``skinfit report`` rewrites its own report folder by design (a report is a view
of the fits, written again from them; :func:`skinfit.report.html.claim_report_folder` refuses a folder
of other files), as a campaign reruns its own stale fits and says so.
"""

from pathlib import Path

from skinfit.errors import InputError

__all__ = ["check_outputs"]


def check_outputs(out, names, *, command, overwrite=False):
    """Refuse (one-line InputError, nothing written) an output folder ``out`` that holds any of
    ``names`` (the files ``command`` writes there) unless ``overwrite``; ``out`` being a file is
    refused always. Call it before any work: a refusal then costs nothing."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(out, f"is a file: --out names the folder {command} writes into (nothing was written)")
    there = [n for n in names if (out / n).exists()]
    if there and not overwrite:
        listed = ", ".join(there[:4]) + (f" and {len(there) - 4} more" if len(there) > 4 else "")
        raise InputError(out, f"holds the results of an earlier {command} ({listed}): --overwrite to replace them, "
                              "or give another --out (nothing was written)")
