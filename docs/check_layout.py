"""Check the built HTML docs in a browser: nothing may run past the body's right edge.

    python docs/check_layout.py BUILD_DIR [--width 1280] [--chromium PATH]

Each page is opened in headless Chromium at a window ``--width`` pixels wide; a script added to
a copy of the page measures every equation, code block, figure, table and paragraph against the
right edge of the text body (``div.body``) and the page prints what it found. Allowed: a table
or a diagram (a ```none block) wider than the body that scrolls inside it (docs/_static/layout.css).
Not allowed: anything else
whose right edge lies past the body's, or an equation or code block that needs a scroll bar (its
end is hidden until the reader scrolls). Prints one line per finding and exits 1 if there is
any, 0 with a count of the pages checked otherwise. Needs Chromium (Debian's ``chromium``); CI
runs it after the docs build (.ci/run).
"""

from __future__ import annotations

import argparse
import html
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

SKIPPED = {"genindex.html", "search.html", "py-modindex.html"}  # the theme's own pages

# Runs once the page has loaded; leaves its findings as JSON in a <pre id="layout-findings">.
PROBE = """
<script>
window.addEventListener("load", () => {
  const body = document.querySelector("div.body");
  const found = [];
  if (body) {
    const right = body.getBoundingClientRect().right;
    const scrolls = (e) => ["auto", "scroll"].includes(getComputedStyle(e).overflowX);
    const insideScroller = (e) => {
      for (let p = e.parentElement; p && p !== body; p = p.parentElement) if (scrolls(p)) return true;
      return false;
    };
    const text = (e) => e.textContent.replace(/\\s+/g, " ").trim().slice(0, 80);
    for (const e of body.querySelectorAll("div.math, pre, img, table, p, li, dt, dd, h1, h2, h3, h4")) {
      if (insideScroller(e)) continue;
      const hidden = e.scrollWidth > e.clientWidth + 1 && scrolls(e);
      const mayScroll = e.tagName === "TABLE" || (e.tagName === "PRE" && e.closest("div.highlight-none"));
      if (hidden && !mayScroll)
        found.push(`${e.tagName.toLowerCase()} needs a scroll bar (${e.scrollWidth} px in ${e.clientWidth}): ${text(e)}`);
      else if (e.getBoundingClientRect().right > right + 2)
        found.push(`${e.tagName.toLowerCase()} runs ${Math.round(e.getBoundingClientRect().right - right)} px past the body: ${text(e)}`);
    }
  } else {
    found.push("no div.body on the page");
  }
  const out = document.createElement("pre");
  out.id = "layout-findings";
  out.textContent = JSON.stringify(found);
  document.documentElement.appendChild(out);
});
</script>
"""


def findings(page: Path, chromium: str, width: int) -> list[str]:
    """What the probe found on ``page`` (a copy with the probe sits beside it while it runs)."""
    probe = page.with_name(page.stem + ".layout-check.html")
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"), encoding="utf-8")
    try:
        dom = subprocess.run(
            [chromium, "--headless", "--no-sandbox", "--disable-gpu", f"--window-size={width},900",
             "--virtual-time-budget=5000", "--dump-dom", probe.as_uri()],
            capture_output=True, text=True, timeout=120, check=False,
        ).stdout  # fmt: skip
    finally:
        probe.unlink()
    match = re.search(r'<pre id="layout-findings">(.*?)</pre>', dom, re.S)
    if match is None:
        return ["the probe did not report (the page did not load in Chromium)"]
    return list(json.loads(html.unescape(match.group(1))))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("build", type=Path, help="the folder sphinx -b html wrote")
    ap.add_argument("--width", type=int, default=1280, help="the browser window's width in pixels (default 1280)")
    ap.add_argument("--chromium", default=shutil.which("chromium") or "chromium", help="the Chromium executable")
    args = ap.parse_args()
    args.build = args.build.resolve()  # Chromium opens the pages by their file URI
    pages = sorted(p for p in [*args.build.glob("*.html"), *args.build.glob("api/*.html")] if p.name not in SKIPPED)
    if not pages:
        print(f"no HTML pages in {args.build}: build the docs first (python -m sphinx -b html docs {args.build})")
        return 1
    bad = 0
    for page in pages:
        for finding in findings(page, args.chromium, args.width):
            print(f"{page.relative_to(args.build)}: {finding}")
            bad += 1
    print(f"{len(pages)} pages checked at {args.width} px: {bad} findings")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
