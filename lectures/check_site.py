"""Check the built lecture site: every formula parses, and nothing loads from the network.

Usage (after building the site, from the repository root):

    .venv/bin/python lectures/check_site.py [lectures/_build/html]

Sphinx passes TeX through to MathJax untouched, so a formula that MathJax
cannot parse does not fail the build; it shows up as an error box in the
reader's browser. This script extracts every inline and display formula from
the built HTML pages and runs it through the MathJax copy that
`sphinx-mathjax-offline` ships in the site (`_static/mathjax/`), with Node.js,
the same TeX packages the pages load, the macros of `_config.yml`, and
undefined macros treated as errors. It also fails if a page references a
remote script, stylesheet or image. Exit status 0 means clean; 1 lists the
problems.

With `--widths`, it also renders each chapter in headless Chromium (network
blocked, 1200-pixel window) and lists display equations wider than the text
column; MathJax 3 does not break long lines, so such equations get a
horizontal scroll bar. This needs `chromium` on `PATH` and takes about a
minute.
"""

from __future__ import annotations

import argparse
import html
import json
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import yaml

LECTURES = Path(__file__).resolve().parent

NODE_SCRIPT = r"""
const fs = require('fs');
const [mathjaxDir, jobsFile] = process.argv.slice(2);
const {macros, formulas} = JSON.parse(fs.readFileSync(jobsFile, 'utf8'));
require(mathjaxDir + '/node-main.js').init({
  loader: {load: ['input/tex']},
  tex: {
    macros: macros,
    packages: {'[-]': ['noundefined']},
    formatError: (jax, err) => { throw err; },
  },
}).then(async (MathJax) => {
  const errors = [];
  for (const f of formulas) {
    try {
      await MathJax.tex2mmlPromise(f.tex, {display: f.display});
    } catch (e) {
      errors.push({where: f.where, tex: f.tex, message: String(e.message || e)});
    }
  }
  process.stdout.write(JSON.stringify(errors));
}).catch((e) => { console.error('MathJax failed to start: ' + e); process.exit(2); });
"""


WIDTH_PROBE = (
    "<script>setTimeout(()=>{const out=[];"
    "document.querySelectorAll('div.math').forEach(d=>{"
    "const m=d.querySelector('mjx-container > mjx-math');if(!m)return;"
    "const e=d.querySelector('.eqno');"
    "const avail=d.getBoundingClientRect().width-(e?e.getBoundingClientRect().width:0);"
    "const w=m.getBoundingClientRect().width;"
    "if(w>avail-8){out.push((d.id||d.textContent.slice(0,50))+' ('+Math.round(w)+'px > '+Math.round(avail)+'px)')}});"
    "const p=document.createElement('pre');p.id='width-probe';p.textContent=JSON.stringify(out);"
    "document.body.appendChild(p);},6000);</script></body>"
)


def too_wide_equations(html_dir: Path, pages: list[Path]) -> list[str]:
    """Render pages in headless Chromium and list display equations wider than the column."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        raise RuntimeError("--widths needs chromium on PATH (apt-get install chromium)")
    problems = []
    for page in pages:
        if "mathjax" not in page.read_text(encoding="utf-8"):
            continue  # a redirect page (index.html) or a page without math
        probe = html_dir / f".width_probe_{page.name}"
        probe.write_text(page.read_text(encoding="utf-8").replace("</body>", WIDTH_PROBE), encoding="utf-8")
        try:
            dom = subprocess.run(
                [browser, "--headless", "--no-sandbox", "--disable-gpu", "--proxy-server=127.0.0.1:9",
                 "--host-resolver-rules=MAP * ~NOTFOUND", "--virtual-time-budget=8000",
                 "--window-size=1200,1600", "--dump-dom", probe.resolve().as_uri()],
                capture_output=True, text=True, timeout=120, check=False,
            ).stdout
        finally:
            probe.unlink()
        found = re.search(r'<pre id="width-probe">([^<]*)</pre>', dom)
        if found is None:
            problems.append(f"{page.name}: the page did not finish rendering")
            continue
        problems += [f"{page.name}: {item}" for item in json.loads(html.unescape(found.group(1)))]
    return problems


class _PageScanner(HTMLParser):
    """Collects math elements and remote resources of one HTML page."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.formulas: list[tuple[str, bool]] = []
        self.remote: list[str] = []
        self._depth = 0  # > 0 while inside a math element
        self._skip = 0  # > 0 while inside its equation number (eqno span)
        self._display = False
        self._buffer: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        attributes = dict(attrs)
        for key in ("src", "href"):
            value = attributes.get(key) or ""
            remote_tag = tag in ("script", "img") or (tag == "link" and attributes.get("rel") == "stylesheet")
            if key in attributes and remote_tag and re.match(r"^(https?:)?//", value):
                self.remote.append(f"<{tag} {key}={value}>")
        classes = (attributes.get("class") or "").split()
        if self._depth:
            self._depth += 1
            if self._skip or "eqno" in classes:
                self._skip += 1
        elif "math" in classes and tag in ("span", "div"):
            self._depth = 1
            self._display = tag == "div"
            self._buffer = []

    def handle_endtag(self, tag: str) -> None:
        if self._depth:
            self._depth -= 1
            if self._skip:
                self._skip -= 1
            if self._depth == 0:
                self.formulas.append(("".join(self._buffer), self._display))

    def handle_data(self, data: str) -> None:
        if self._depth and not self._skip:
            self._buffer.append(data)


def _strip_delimiters(tex: str) -> str:
    tex = html.unescape(tex).strip()
    for left, right in (("\\(", "\\)"), ("\\[", "\\]"), ("$$", "$$")):
        if tex.startswith(left) and tex.endswith(right):
            return tex[len(left) : -len(right)].strip()
    return tex


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("html_dir", nargs="?", type=Path, default=LECTURES / "_build" / "html")
    parser.add_argument("--widths", action="store_true", help="also flag equations wider than the column (needs chromium)")
    args = parser.parse_args()

    mathjax_dir = args.html_dir / "_static" / "mathjax"
    if not (mathjax_dir / "node-main.js").exists():
        print(f"error: {mathjax_dir}/node-main.js not found; build the site first", file=sys.stderr)
        return 1
    node = shutil.which("node") or shutil.which("nodejs")
    if node is None:
        print("error: Node.js is needed to check the formulas (apt-get install nodejs)", file=sys.stderr)
        return 1

    config = yaml.safe_load((LECTURES / "_config.yml").read_text())
    macros = config["sphinx"]["config"]["mathjax3_config"]["tex"]["macros"]

    formulas, remote = [], []
    pages = sorted(p for p in args.html_dir.glob("*.html") if p.name not in ("genindex.html", "search.html"))
    for page in pages:
        scanner = _PageScanner()
        scanner.feed(page.read_text(encoding="utf-8"))
        remote += [f"{page.name}: {item}" for item in scanner.remote]
        for number, (tex, display) in enumerate(scanner.formulas):
            formulas.append({"where": f"{page.name} #{number}", "tex": _strip_delimiters(tex), "display": display})

    jobs = args.html_dir / ".check_site_jobs.json"
    script = args.html_dir / ".check_site.js"
    jobs.write_text(json.dumps({"macros": macros, "formulas": formulas}))
    script.write_text(NODE_SCRIPT)
    try:
        result = subprocess.run(
            [node, str(script), str(mathjax_dir.resolve()), str(jobs)],
            capture_output=True, text=True, check=False,
        )
    finally:
        jobs.unlink()
        script.unlink()
    if result.returncode != 0:
        print(result.stderr, file=sys.stderr)
        return 1
    errors = json.loads(result.stdout)

    for error in errors:
        print(f"math error in {error['where']}: {error['message']}\n    {error['tex'][:200]}")
    for item in remote:
        print(f"remote resource: {item}")
    print(f"checked {len(formulas)} formulas on {len(pages)} pages: "
          f"{len(errors)} math errors, {len(remote)} remote resources")
    wide = []
    if args.widths:
        wide = too_wide_equations(args.html_dir, pages)
        for item in wide:
            print(f"equation wider than the text column: {item}")
        print(f"checked equation widths on {len(pages)} pages: {len(wide)} too wide")
    return 1 if errors or remote or wide else 0


if __name__ == "__main__":
    sys.exit(main())
