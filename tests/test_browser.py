"""The student's notebooks in JupyterLab, in a real browser (headless Chromium).

JupyterLab serves a copy of the student release on a loopback port; Chromium, with every other
address blocked, opens a student notebook, runs its first cells through JupyterLab's own commands,
and the test reads the page: math typeset by JupyterLab's MathJax, hw0's clip playing, and hw3's
"be the annotator" widget clicked through with mouse events, its status line advancing, a sign of
progress while each pair renders, and the unfinished `train_reward_model` stub's error shown in
the widget itself. Chromium is driven over its DevTools protocol (``websocket-client``), so nothing
is downloaded at run time. Needs Debian's ``chromium`` (``make setup`` installs it as root);
skipped, saying so, where there is none.
"""
from __future__ import annotations

import itertools
import json
import os
import secrets
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import nbformat
import numpy as np
import pytest

from rlcourse.video import render_rollout

REPO = Path(__file__).resolve().parents[1]
BROWSER = shutil.which("chromium") or shutil.which("chromium-browser")


def test_hw0_clip_runs_past_the_end_of_the_episode():
    """hw0's clip shows the whole CLIP_SECONDS: the random hopper's episode ends far sooner."""
    rng = np.random.default_rng(0)

    def policy(obs):
        return rng.uniform(-1, 1, size=(len(obs), 3))

    short = render_rollout(policy, "Hopper-v5", seed=0, seconds=1.0, size=32, fps=10)
    whole = render_rollout(policy, "Hopper-v5", seed=0, seconds=1.0, size=32, fps=10, past_the_end=True)
    assert len(short) < 6 and len(whole) == 11, (len(short), len(whole))  # a frame at t = 0, then 10 a second


# --------------------------------------------------------------------------- the browser


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(what: str, probe, timeout: float, interval: float = 0.25):
    """Poll ``probe()`` until it returns something truthy; fail naming ``what`` after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        value = probe()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(interval)


class DevTools:
    """The few DevTools-protocol calls the test needs, on one page of a headless Chromium."""

    def __init__(self, profile: Path, log):
        import websocket

        self.process = subprocess.Popen(
            [BROWSER, "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             f"--user-data-dir={profile}", "--remote-debugging-port=0", "--window-size=1280,1000",
             # every address but loopback goes to a closed port: nothing is fetched from the network
             "--proxy-server=127.0.0.1:9", "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1",
             "about:blank"],
            stdout=log, stderr=log)
        port_file = profile / "DevToolsActivePort"
        port = _wait("Chromium's DevTools port", lambda: port_file.exists() and port_file.read_text().split()[:1], 30)[0]
        targets = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10).read())
        page = next(t for t in targets if t["type"] == "page")
        self.socket = websocket.create_connection(page["webSocketDebuggerUrl"], timeout=60, suppress_origin=True)
        self.ids = itertools.count(1)

    def send(self, method: str, **params):
        call = next(self.ids)
        self.socket.send(json.dumps({"id": call, "method": method, "params": params}))
        while True:
            message = json.loads(self.socket.recv())
            if message.get("id") == call:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message.get("result", {})

    def js(self, expression: str):
        """The value of a JavaScript expression in the page (promises awaited)."""
        result = self.send("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression[:80]}...: {result['exceptionDetails'].get('exception', {}).get('description')}")
        return result["result"].get("value")

    def wait_js(self, what: str, expression: str, timeout: float = 60):
        return _wait(what, lambda: self.js(expression), timeout)

    def click(self, element: str) -> None:
        """A real left click (mouse down and up) at the centre of ``element`` (a JavaScript expression)."""
        box = self.js(f"(() => {{ const e = {element}; if (!e) return null;"
                      " e.scrollIntoView({block: 'center'}); const r = e.getBoundingClientRect();"
                      " return [r.x + r.width / 2, r.y + r.height / 2]; })()")
        assert box, f"nothing on the page is {element}"
        for kind in ("mouseMoved", "mousePressed", "mouseReleased"):
            self.send("Input.dispatchMouseEvent", type=kind, x=box[0], y=box[1], button="left", clickCount=1)

    def screenshot(self, path: Path) -> None:
        import base64

        path.write_bytes(base64.b64decode(self.send("Page.captureScreenshot", format="png")["data"]))

    def close(self) -> None:
        self.socket.close()
        self.process.terminate()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()


def _annotator_notebook(student: Path) -> nbformat.NotebookNode:
    """hw3's student notebook cut to what its widget needs, as a student who ran those cells has it:
    the parameters, ``FAST = True`` injected after them (papermill's convention), the budgets with
    ``INTERACTIVE = True`` after them, the setup and stub cells (every stub still unfinished), the
    cell that loads the Hopper preferences, and the widget's cell with its heading."""
    nb = nbformat.read(student, as_version=4)
    cells = nb.cells
    params = next(i for i, c in enumerate(cells) if "parameters" in c.metadata.get("tags", []))
    budgets = next(i for i, c in enumerate(cells) if c.cell_type == "code" and i > params)
    keep = [cells[params], nbformat.v4.new_code_cell("FAST = True"), cells[budgets],
            nbformat.v4.new_code_cell("INTERACTIVE = True")]
    for cell in cells[budgets + 1:]:
        meta = cell.metadata.get("nbgrader", {})
        if cell.cell_type != "code":
            if cell.source.startswith("## ") and "be the annotator" in cell.source.splitlines()[0]:
                keep.append(cell)
        elif ("setup" in cell.metadata.get("tags", []) or meta.get("solution")
              or "load_hopper_preferences()" in cell.source or "annotate_yourself" in cell.source):
            keep.append(cell)
    nb.cells = keep
    return nb


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A JupyterLab on a loopback port serving a fresh student release, and a headless Chromium."""
    if BROWSER is None:
        pytest.skip("no chromium on PATH: `apt-get install chromium` (make setup does it when run as root)")
    pytest.importorskip("websocket", reason="websocket-client is not installed")
    from autograder.authoring.release import build_student_release

    tmp = tmp_path_factory.mktemp("browser")
    course = build_student_release(tmp / "course")
    nbformat.write(_annotator_notebook(course / "assignments/hw3_preferences/hw3_preferences.ipynb"),
                   course / "assignments/hw3_preferences/annotator_check.ipynb")
    settings = tmp / "settings/@jupyterlab/apputils-extension"
    settings.mkdir(parents=True)
    (settings / "notification.jupyterlab-settings").write_text('{"fetchNews": "false", "checkForUpdates": false}')
    port, token = _free_port(), secrets.token_hex(16)
    env = dict(os.environ, PYTHONPATH=str(course), RLCOURSE_DATASETS=str(course / "datasets"),
               PATH=f"{Path(sys.executable).parent}:{os.environ.get('PATH', '')}",
               JUPYTER_CONFIG_DIR=str(tmp / "config"), JUPYTER_RUNTIME_DIR=str(tmp / "runtime"),
               IPYTHONDIR=str(tmp / "ipython"), MPLCONFIGDIR=str(tmp / "mpl"))
    log = open(tmp / "lab.log", "w")
    server = subprocess.Popen(
        [sys.executable, "-m", "jupyterlab", "--no-browser", "--ip=127.0.0.1", f"--port={port}",
         "--ServerApp.port_retries=0", f"--IdentityProvider.token={token}", f"--ServerApp.root_dir={course}",
         f"--LabApp.user_settings_dir={tmp / 'settings'}", f"--LabApp.workspaces_dir={tmp / 'workspaces'}",
         "--LabApp.expose_app_in_browser=True", "--LabApp.news_url=None", "--ServerApp.allow_root=True"],
        cwd=course, env=env, stdout=log, stderr=subprocess.STDOUT)
    browser = None
    try:
        def up():
            try:
                return urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status?token={token}", timeout=2).status == 200
            except OSError:
                assert server.poll() is None, f"JupyterLab exited: {(tmp / 'lab.log').read_text()[-2000:]}"
                return False

        _wait("JupyterLab to answer", up, 90, interval=0.5)
        browser = DevTools(tmp / "profile", log)
        browser.tmp = tmp
        browser.send("Emulation.setFocusEmulationEnabled", enabled=True)  # headless, the page never has focus
        browser.send("Page.navigate", url=f"http://127.0.0.1:{port}/lab?reset&token={token}")
        browser.wait_js("JupyterLab to start", "!!(window.jupyterapp && window.jupyterapp.shell"
                        " && window.jupyterapp.commands.hasCommand('docmanager:open'))", 90)
        yield browser
    finally:
        if browser is not None:
            browser.close()
        server.terminate()
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            server.kill()
        log.close()


def _open(lab: DevTools, notebook: str) -> None:
    """Open ``notebook`` in JupyterLab, wait for its kernel, and make it the current panel."""
    lab.js(f"void window.jupyterapp.commands.execute('docmanager:open', {{path: {json.dumps(notebook)}}})")
    panel = f"[...window.jupyterapp.shell.widgets('main')].find(w => w.context && w.context.path === {json.dumps(notebook)})"
    lab.wait_js(f"{notebook} to open with an idle kernel",
                f"(() => {{ const w = {panel}; const k = w && w.sessionContext.session && w.sessionContext.session.kernel;"
                " return !!(k && k.status === 'idle' && w.content.widgets.length); })()", 90)
    lab.js(f"window.jupyterapp.shell.activateById({panel}.id)")
    lab.wait_js(f"{notebook} to be the current panel",
                f"window.jupyterapp.shell.currentWidget === {panel}", 10)


def _run_all(lab: DevTools) -> None:
    """Run > Run All Cells (JupyterLab stops at the first cell that raises, as it does for a student)."""
    lab.js("void window.jupyterapp.commands.execute('notebook:run-all-cells')")  # not awaited: polled after


CELLS = "window.jupyterapp.shell.currentWidget.content.widgets"


def button(text: str) -> str:
    """The widget's button that says ``text``, as a JavaScript expression."""
    return f"[...document.querySelectorAll('.widget-vbox button')].find(b => b.textContent.trim() === {json.dumps(text)})"


def _cell_errors(lab: DevTools, upto: int) -> list:
    """(index, error name) of the code cells before ``upto`` whose outputs hold an error."""
    return lab.js(f"{CELLS}.slice(0, {upto}).flatMap((c, i) => c.model.type !== 'code' ? [] :"
                  " c.model.toJSON().outputs.filter(o => o.output_type === 'error').map(o => [i, o.ename]))")


def _math_is_typeset(lab: DevTools) -> dict:
    """Rendered Markdown with math: MathJax containers, MathJax errors, and TeX left as text."""
    return lab.js("(() => { const md = [...document.querySelectorAll('.jp-MarkdownOutput')];"
                  " return {typeset: md.reduce((n, e) => n + e.querySelectorAll('mjx-container').length, 0),"
                  " errors: md.reduce((n, e) => n + e.querySelectorAll('mjx-merror, [data-mjx-error]').length, 0),"
                  " raw: md.filter(e => /\\$[^$\\s][^$]*\\$/.test(e.innerText)).length}; })()")


@pytest.mark.slow
def test_hw0_in_jupyterlab_runs_its_first_cells_typesets_math_and_plays_its_clip(lab):
    """hw0: Run All runs every cell before the first unfinished stub's check; math is typeset; the
    clip plays for its seconds."""
    _open(lab, "assignments/hw0_setup/hw0_setup.ipynb")
    nb = nbformat.read(REPO / "assignments/hw0_setup/hw0_setup.ipynb", as_version=4)
    first_check = next(i for i, c in enumerate(nb.cells) if "check" in c.metadata.get("tags", []))
    _run_all(lab)
    try:
        lab.wait_js("the first public check to run (and stop Run All)",
                    f"{CELLS}[{first_check}].model.executionCount !== null", 120)
        assert _cell_errors(lab, first_check) == [], "a cell before the first stub's check raised"
        assert lab.js(f"{CELLS}.slice(0, {first_check}).every(c => c.model.type !== 'code' || c.model.executionCount)"), \
            "a code cell before the first stub's check did not run"
        assert lab.js(f"{CELLS}[{first_check}].model.toJSON().outputs.some(o => o.ename === 'NotImplementedError')"), \
            "the first check should stop at the unfinished stub"
        math = _math_is_typeset(lab)
        assert math["typeset"] >= 5 and math["errors"] == 0 and math["raw"] == 0, math
        # scrolled to, as a reader does (Chromium pauses a muted autoplaying video out of view)
        lab.wait_js("the clip in the output", "(() => { const v = document.querySelector('.jp-OutputArea video');"
                    " if (v) v.scrollIntoView({block: 'center'}); return !!v; })()", 30)
        clip = lab.wait_js("the clip to play for a second", "(() => { const v = document.querySelector('.jp-OutputArea video');"
                           " return !v.paused && v.currentTime > 1 && {duration: v.duration, width: v.videoWidth}; })()", 30)
        assert clip["duration"] >= 1.9 and clip["width"] == 240, clip
    except Exception:
        lab.screenshot(lab.tmp / "hw0.png")
        raise


@pytest.mark.slow
def test_hw3_annotator_widget_advances_shows_progress_and_reports_the_unfinished_stub_in_place(lab):
    """hw3's widget in JupyterLab: each click advances its status line, the buttons show progress while
    the next pair renders, and after the last answer `train_reward_model`'s NotImplementedError is
    written, in plain words, in the widget's output area, not lost in JupyterLab's log console."""
    _open(lab, "assignments/hw3_preferences/annotator_check.ipynb")
    _run_all(lab)
    status = ".widget-vbox > .widget-label"
    try:
        first = lab.wait_js("the widget's first pair", f"(() => {{ const s = document.querySelector('{status}');"
                            " return !!document.querySelector('.widget-vbox video') && s"
                            " && /^pair 1 of \\d+: which hops better\\?$/.test(s.textContent) && s.textContent; })()", 120)
        n = int(first.split()[3].rstrip(":"))  # the FAST labels and the retest pairs asked again
        assert n >= 2, first
        assert _cell_errors(lab, 10**6) == [], "a cell raised before the widget"
        # every text the status line and the shown buttons go through (the rating scale is hidden), recorded
        lab.js(f"(() => {{ window.seen = []; const s = document.querySelector('{status}');"
               " const note = () => window.seen.push([s.textContent,"
               " [...document.querySelectorAll('.widget-vbox button')].filter(b => b.offsetParent).every(b => b.disabled)]);"
               " new MutationObserver(note).observe(document.querySelector('.widget-vbox'),"
               " {subtree: true, childList: true, characterData: true, attributes: true}); })()")
        for k in range(2, n + 1):
            lab.click(button("left is better"))
            lab.wait_js(f"pair {k}", f"document.querySelector('{status}').textContent === 'pair {k} of {n}: which hops better?'"
                        " && [...document.querySelectorAll('.widget-vbox button')].filter(b => b.offsetParent).every(b => !b.disabled)", 60)
            assert [f"rendering pair {k} of {n}...", True] in lab.js("window.seen"), \
                f"no sign of progress while pair {k} rendered: {lab.js('window.seen')}"
        lab.click(button("can't tell"))  # the last answer: the widget trains with the unfinished stub
        message = lab.wait_js("the stub's error in the widget's output area",
                              "(document.querySelector('.widget-vbox .widget-output') || {}).innerText", 60)
        assert "`train_reward_model` is not implemented yet" in message, message
        assert lab.js(f"document.querySelector('{status}').textContent").startswith("stopped")
        assert [f"training a reward model on your {n} labels...", True] in lab.js("window.seen")
    except Exception:
        lab.screenshot(lab.tmp / "hw3.png")
        raise
