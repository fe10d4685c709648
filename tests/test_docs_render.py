"""The documentation site as a reader sees it (issue 34).

Source checks (no build): every guide has the five sections in order and is at most 8 KB; no page under
docs/ names a date or a load average (history lives in CHANGELOG.md and the registry's READMEs).

Built checks: the site is built once per session with ``sphinx -W`` (or ``docs/_build/html`` is used when it
is newer than every source, as after ``make docs``; ``SPHRELAX_DOCS_HTML=DIR`` names another build). In the
built guides and front page: no emphasis (``<em>``) that a ``_`` or ``*`` inside a formula made, no ``$`` of
a formula left unparsed, every image a page names exists, and every guide shows its gallery figure. Then
headless Chromium (Debian's ``chromium``) opens the front page and one guide: each image must have loaded
in the browser, and the screenshot must show a picture (not a blank area) where the first figure is.
"""
from __future__ import annotations

import functools
import html
import html.parser
import http.server
import json
import os
import re
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
GUIDES = sorted((DOCS / "guides").glob("*.md"))
SECTIONS = ["What it does", "Quick start", "The parameters that matter", "When to use it, and when not",
            "Limits and known differences from the paper"]
MAX_BYTES = 8 * 1024
PAGES = ["index.html"] + [f"guides/{p.stem}.html" for p in GUIDES]
# pages checked for emphasis inside formulas: the guides, the front page and the other hand-written pages
TEXT_PAGES = PAGES + ["getting_started.html", "conventions.html", "which_method.html", "cli.html", "layout.html"]
# a date (2026-12-02, 2 December 2026, Dec 2026) or a load average
HISTORY = re.compile(r"\b(19|20)\d\d-\d\d-\d\d\b|\b\d{1,2} (January|February|March|April|May|June|July|August|"
                     r"September|October|November|December) (19|20)\d\d\b|\bload average|\bat load\b|\bload \d",
                     re.IGNORECASE)
GENERATED = ("gallery", "generated", "_build")
FORMULA_CHARS = set("=∇Σ∑∫|^_<>≤≥·√∂ρφγΩωεδΔαβλμνσθχψ+−*/")
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--hide-scrollbars", "--window-size=1280,1600"]


# -- sources ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("guide", GUIDES, ids=lambda p: p.name)
def test_guide_has_the_five_sections_and_fits(guide):
    text = guide.read_text()
    headings = re.findall(r"^## (.+?)\s*$", text, flags=re.M)
    main = [h for h in headings if h in SECTIONS]
    assert main == SECTIONS, f"{guide.name}: sections {headings}"
    assert len(text.encode()) <= MAX_BYTES, f"{guide.name} is {len(text.encode())} bytes"
    assert re.search(r"!\[[^\]]+\]\(\.\./gallery/images/sphx_glr_\w+_001\.png\)",
                     text.split("## Quick start")[0]), f"{guide.name}: no gallery figure under 'What it does'"


def _doc_sources():
    return [p for p in sorted(DOCS.rglob("*.md")) if not set(p.relative_to(DOCS).parts) & set(GENERATED)]


@pytest.mark.parametrize("page", _doc_sources(), ids=lambda p: p.relative_to(DOCS).as_posix())
def test_no_dates_or_load_averages(page):
    hits = [line.strip() for line in page.read_text().splitlines() if HISTORY.search(line)]
    assert not hits, f"{page.relative_to(ROOT)} tells history (move it to CHANGELOG.md): {hits[:3]}"


def test_cli_page_has_a_generated_table_per_command():
    """docs/cli.md names every registered command in a ``{cli-options}`` directive (tables from the parsers)."""
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        from cli_options import command_parsers, option_rows
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    text = (DOCS / "cli.md").read_text()
    listed = set(re.findall(r"^```\{cli-options\} (\S+)\s*$", text, flags=re.M))
    parsers = command_parsers()
    assert listed == set(parsers), f"docs/cli.md lists {sorted(listed)}, the parser has {sorted(parsers)}"
    flags = {row[0].split()[0] for row in option_rows(parsers["pack"][0])}
    assert {"--walls", "--periodic", "--cell", "--wall-mode", "--momentum"} <= flags


# -- the built site --------------------------------------------------------------------------------------------
def _newest_source():
    files = [*DOCS.rglob("*.md"), *DOCS.rglob("*.rst"), DOCS / "conf.py", *(DOCS / "_ext").glob("*.py"),
             *(ROOT / "examples" / "gallery").glob("*.py")]
    return max(f.stat().st_mtime for f in files if not set(f.relative_to(ROOT).parts) & {"_build", "generated"})


@pytest.fixture(scope="session")
def built_html(tmp_path_factory):
    """A built site: ``$SPHRELAX_DOCS_HTML``, an up-to-date ``docs/_build/html``, or a fresh ``sphinx -W`` build."""
    given = os.environ.get("SPHRELAX_DOCS_HTML")
    if given:
        return Path(given)
    default = DOCS / "_build" / "html"
    if (default / "index.html").exists() and (default / "index.html").stat().st_mtime > _newest_source():
        return default
    out = tmp_path_factory.mktemp("html")
    env = dict(os.environ, MPLBACKEND="Agg",
               PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS),
                           str(out)], capture_output=True, text=True, env=env, timeout=3600)
    assert done.returncode == 0, f"sphinx -W failed:\n{done.stderr[-5000:]}"
    return out


class _Page(html.parser.HTMLParser):
    """The article of a built page: its images, its emphasis with the text around it, and its plain text."""

    SKIP = {"code", "pre", "script", "style"}

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.images, self.ems, self.text = [], [], []
        self._stack, self._in_article, self._skip, self._math, self._em = [], 0, 0, 0, None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        classes = (attrs.get("class") or "").split()
        if tag == "article" or (tag == "main" and not self._in_article):
            self._in_article += 1
        if tag in ("br", "img", "hr", "input", "meta", "link"):
            if tag == "img" and self._in_article:
                self.images.append(attrs.get("src", ""))
            return
        self._stack.append((tag, "math" in classes))
        if tag in self.SKIP:
            self._skip += 1
        if "math" in classes:
            self._math += 1
        if tag == "em" and self._in_article and not (self._skip or self._math):
            before = "".join(self.text)[-1:]
            self._em = {"before": before, "text": ""}

    def handle_endtag(self, tag):
        while self._stack:
            open_tag, is_math = self._stack.pop()
            if open_tag in self.SKIP:
                self._skip -= 1
            if is_math:
                self._math -= 1
            if open_tag == "em" and self._em is not None:
                self._em["after_at"] = len("".join(self.text))
                self.ems.append(self._em)
                self._em = None
            if open_tag in ("article", "main") and self._in_article:
                self._in_article -= 1
            if open_tag == tag:
                break

    def handle_data(self, data):
        if not self._in_article or self._skip or self._math:
            return
        if self._em is not None:
            self._em["text"] += data
        self.text.append(data)


def _parse(path):
    page = _Page()
    page.feed(path.read_text())
    text = "".join(page.text)
    for em in page.ems:
        em["after"] = text[em.pop("after_at"):][:1]
    return page, text


def _formula_emphasis(em):
    """An ``<em>`` that a ``_`` or ``*`` inside a formula made: inside a word, or around formula symbols."""
    inside_word = bool(re.match(r"[\w)\]|]", em["before"])) or bool(re.match(r"[\w(|]", em["after"]))
    return inside_word or bool(set(em["text"]) & FORMULA_CHARS)


def test_formula_emphasis_detector():
    """The detector flags ``|∇C|_avg ... in 2c_`` and ``a*b*c`` and spares prose emphasis."""
    assert _formula_emphasis({"before": "|", "text": "avg over the unfrozen ones in 2c", "after": " "})
    assert _formula_emphasis({"before": "a", "text": "b", "after": "c"})
    assert _formula_emphasis({"before": " ", "text": "x = y", "after": " "})
    assert not _formula_emphasis({"before": " ", "text": "Analysis of the particle relaxation method", "after": " "})
    assert not _formula_emphasis({"before": "(", "text": "not", "after": ")"})


@pytest.mark.slow
@pytest.mark.parametrize("name", TEXT_PAGES)
def test_built_page_has_no_formula_emphasis(built_html, name):
    page, text = _parse(built_html / name)
    assert text.strip(), f"{name}: no article text found"
    bad = [em for em in page.ems if _formula_emphasis(em)]
    assert not bad, f"{name}: emphasis inside formula text: {bad[:3]}"
    stray = [m.group(0) for m in re.finditer(r".{0,30}\$.{0,30}", text)]
    assert not stray, f"{name}: a '$' formula was not parsed as math: {stray[:3]}"


@pytest.mark.slow
@pytest.mark.parametrize("name", PAGES)
def test_built_page_shows_its_figures(built_html, name):
    path = built_html / name
    page, _ = _parse(path)
    assert page.images, f"{name}: no figure"
    for src in page.images:
        if src.startswith(("http:", "https:", "data:")):
            continue
        assert (path.parent / src.split("#")[0]).resolve().exists(), f"{name}: missing image {src}"
    assert any("sphx_glr_" in src for src in page.images), f"{name}: no gallery figure"


# -- the built site in a browser -------------------------------------------------------------------------------
PROBE = """<!doctype html><html><body style="margin:0">
<iframe id="f" src="/{page}" style="border:0;width:1280px;height:1600px"></iframe><pre id="out">pending</pre>
<script>
const f = document.getElementById("f");
f.addEventListener("load", () => {{
  const d = f.contentDocument;
  const images = Array.from(d.images).map(i => {{ const r = i.getBoundingClientRect();
    return {{src: i.getAttribute("src"), complete: i.complete, width: i.naturalWidth, height: i.naturalHeight,
             x: r.left, y: r.top, w: r.width, h: r.height}}; }});
  document.getElementById("out").textContent = JSON.stringify({{title: d.title, images: images}});
}});
</script></body></html>"""


def _chromium():
    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def served(built_html):
    """The built site on a local HTTP server (``/__probe/PAGE`` is a page that reports PAGE's images)."""

    class Handler(http.server.SimpleHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 - http.server's name
            if self.path.startswith("/__probe/"):
                body = PROBE.format(page=self.path[len("/__probe/"):]).encode()
                self.send_response(200)
                self.send_header("Content-Type", "text/html; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)
                return
            super().do_GET()

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=str(built_html)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()


def _run_chromium(args, profile):
    done = subprocess.run([_chromium(), *CHROMIUM_FLAGS, f"--user-data-dir={profile}", *args],
                          capture_output=True, text=True, timeout=180)
    return done


@pytest.mark.slow
@pytest.mark.parametrize("name", ["index.html", "guides/bipi.html"])
def test_page_shows_its_figure_in_chromium(served, name, tmp_path):
    if _chromium() is None:
        pytest.skip("chromium is not installed (Debian: apt-get install -y chromium): the browser check did not run")
    import matplotlib.image

    done = _run_chromium(["--virtual-time-budget=20000", "--dump-dom", f"{served}/__probe/{name}"], tmp_path / "p1")
    found = re.search(r'<pre id="out">(.*?)</pre>', done.stdout, flags=re.S)
    assert found and found.group(1) != "pending", f"{name}: the page did not load in chromium\n{done.stderr[-2000:]}"
    report = json.loads(html.unescape(found.group(1)))
    figures = [i for i in report["images"] if "sphx_glr_" in (i["src"] or "")]
    assert figures, f"{name}: no gallery figure in the page: {report}"
    visible = [i for i in figures if i["y"] < 1600 and i["h"] > 20]
    assert visible, f"{name}: no gallery figure in the first screen: {figures}"
    broken = [i["src"] for i in visible if not (i["complete"] and i["width"] > 0)]
    assert not broken, f"{name}: images that did not load: {broken}"

    png = tmp_path / "page.png"
    _run_chromium(["--virtual-time-budget=20000", f"--screenshot={png}", f"{served}/{name}"], tmp_path / "p2")
    assert png.exists(), f"{name}: chromium wrote no screenshot"
    shot = matplotlib.image.imread(png)[..., :3]
    first = visible[0]
    y0, y1 = int(first["y"]) + 2, int(min(first["y"] + first["h"], shot.shape[0])) - 2
    x0, x1 = int(first["x"]) + 2, int(min(first["x"] + first["w"], shot.shape[1])) - 2
    area = shot[y0:y1, x0:x1]
    assert area.size, f"{name}: the figure's area {first} is outside the screenshot {shot.shape}"
    not_white = (area.min(axis=2) < 0.9).mean()
    assert area.std() > 0.05 and not_white > 0.01, (
        f"{name}: the figure's area is blank in the screenshot (std {area.std():.3f}, {not_white:.1%} not white)")

