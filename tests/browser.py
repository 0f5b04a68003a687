"""Render a report in headless Chromium and read back what the page found about itself.

A copy of the report's index.html gets a script as the first thing in <head>: it records
console errors and uncaught exceptions and, once the page has loaded, every image that did
not load and every element whose content is wider than its box (a cut table column, a
figure wider than the page), into a <pre id="skinfit-findings"> that ``--dump-dom`` prints.
"""

import json
import re
import shutil
import subprocess
from pathlib import Path

PROBE = """<script>
(function () {
  var found = {console: [], images: [], overflow: [], loaded: false};
  var error = console.error;
  console.error = function () { found.console.push(Array.prototype.join.call(arguments, " ")); error.apply(console, arguments); };
  window.addEventListener("error", function (e) {
    if (e.target && e.target.tagName === "IMG") return;  // reported below as an image
    found.console.push(String(e.message || e));
  }, true);
  function describe(el) {
    return el.tagName.toLowerCase() + (el.id ? "#" + el.id : "") +
      (el.className && typeof el.className === "string" ? "." + el.className.trim().replace(/ +/g, ".") : "") +
      " '" + (el.textContent || el.getAttribute("src") || "").trim().slice(0, 60) + "'";
  }
  window.addEventListener("load", function () {
    document.querySelectorAll("img").forEach(function (img) {
      if (!img.complete || img.naturalWidth === 0) found.images.push(img.getAttribute("src"));
    });
    document.querySelectorAll("body, body *").forEach(function (el) {
      if (el.id === "skinfit-findings" || el.offsetParent === null && el.tagName !== "BODY") return;  // not shown
      if (el.closest("details:not([open])") && el.tagName !== "SUMMARY" && el.tagName !== "DETAILS") return;
      if (el.scrollWidth > el.clientWidth + 1 && el.clientWidth > 0) found.overflow.push(describe(el) +
        " content " + el.scrollWidth + " px in a " + el.clientWidth + " px box");
    });
    found.page_width = document.documentElement.scrollWidth;
    found.loaded = true;
    var pre = document.createElement("pre");
    pre.id = "skinfit-findings";
    pre.textContent = JSON.stringify(found);
    document.body.appendChild(pre);
  });
})();
</script>"""


def chromium():
    """Path of a Chromium executable, or None."""
    return next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)


def _flags(exe):
    return [exe, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--window-size=1280,1000",
            "--allow-file-access-from-files", "--virtual-time-budget=15000"]


def inspect(report_dir, work_dir, screenshot=None):
    """Findings of the report in ``report_dir`` rendered at 1280 px wide: a dict with
    ``console``, ``images``, ``overflow`` (lists), ``page_width`` and ``loaded``."""
    exe = chromium()
    report_dir, work_dir = Path(report_dir).resolve(), Path(work_dir)
    work_dir.mkdir(parents=True, exist_ok=True)
    html = (report_dir / "index.html").read_text(encoding="utf-8")
    probe = report_dir / f".probe-{work_dir.name}.html"  # beside the report: its links resolve alike
    probe.write_text(html.replace("<head>", "<head>\n" + PROBE, 1), encoding="utf-8")
    try:
        out = subprocess.run(_flags(exe) + ["--dump-dom", probe.as_uri()], capture_output=True, text=True,
                             timeout=180)
        if screenshot is not None:
            subprocess.run(_flags(exe)[:-2] + ["--window-size=1280,6000", f"--screenshot={screenshot}",
                                               (report_dir / "index.html").as_uri()],
                           capture_output=True, timeout=180)
    finally:
        probe.unlink()
    m = re.search(r'<pre id="skinfit-findings">(.*?)</pre>', out.stdout, re.S)
    if not m:
        raise RuntimeError(f"chromium printed no findings (exit {out.returncode}): {out.stderr[-2000:]}")
    import html as html_module

    return json.loads(html_module.unescape(m.group(1)))
