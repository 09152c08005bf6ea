"""Notebook widgets: callbacks that report their errors where the student looks, and hw3's annotator.

A widget's callback runs in the kernel when a button is clicked, outside any cell, so an exception
it raises does not reach the notebook: JupyterLab sends it to its log console, and the widget just
stops. Every callback here is wrapped by :func:`report_errors`, which writes the error, in plain
words, into the widget's own output area. A callback that takes seconds shows it (:func:`busy`):
its buttons are disabled and its status line says what is happening until it returns.
"""
from __future__ import annotations

import base64
import contextlib
import functools
from concurrent.futures import Future, ThreadPoolExecutor
import sys
import tempfile
import traceback
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import numpy as np

_THIS_FILE = str(Path(__file__).resolve())
# Code that is not the student's: the installed libraries and rlcourse itself.
_LIBRARY_PREFIXES = tuple({sys.prefix, sys.base_prefix, sys.exec_prefix, str(Path(__file__).resolve().parent)})


def _culprit(err: BaseException) -> str | None:
    """The function that raised ``err``: the innermost frame for ``NotImplementedError`` (the stub
    itself), else the innermost frame outside this module and the installed libraries (the
    student's code), else the innermost frame. ``None`` when that frame is not a named function."""
    frames = [f for f in traceback.extract_tb(err.__traceback__) if f.filename != _THIS_FILE]
    if not frames:
        return None
    if not isinstance(err, NotImplementedError):
        own = [f for f in frames if not f.filename.startswith(_LIBRARY_PREFIXES)]
        frames = own or frames
    name = frames[-1].name
    return None if name.startswith("<") else name


def explain(err: BaseException) -> str:
    """One sentence a student can act on: what failed, in which function, and what to do next."""
    name = _culprit(err)
    where = f"`{name}`" if name else "a function this widget calls"
    if isinstance(err, NotImplementedError):
        return (f"{where} is not implemented yet: fill in its cell, run it, "
                "then click again.")
    detail = str(err).strip() or "(no message)"
    return f"{where} raised {type(err).__name__}: {detail}"


def report_errors(output, status=None, on_error: Callable[[], None] | None = None) -> Callable:
    """Decorate a widget callback so that an exception shows in ``output`` (an ``ipywidgets.Output``).

    The message of :func:`explain` goes first; for anything but ``NotImplementedError`` the
    traceback follows, so the failing line can be found. ``status`` (a widget with a ``value``), when
    given, is set to a short note pointing at the message, and ``on_error`` runs after (to re-enable
    buttons, say). The exception is not re-raised: there is no cell for it to reach.
    """
    def wrap(callback: Callable) -> Callable:
        @functools.wraps(callback)
        def guarded(*args: Any, **kwargs: Any) -> Any:
            try:
                return callback(*args, **kwargs)
            except Exception as err:  # noqa: BLE001 - every error must reach the student, whatever it is
                output.append_stderr(explain(err) + "\n")
                if not isinstance(err, NotImplementedError):
                    output.append_stderr("".join(traceback.format_exception(err)))
                if status is not None:
                    status.value = "stopped: the message below says why"
                if on_error is not None:
                    on_error()
                return None
        return guarded
    return wrap


@contextlib.contextmanager
def busy(status, buttons: Sequence, message: str) -> Iterator[None]:
    """While the block runs: ``buttons`` disabled and ``status`` showing ``message`` (a sign of
    progress for work that takes seconds). The buttons come back even if the block raises."""
    for button in buttons:
        button.disabled = True
    status.value = message
    try:
        yield
    finally:
        for button in buttons:
            button.disabled = False


def video_html(frames: np.ndarray, fps: int = 12, width: int = 420) -> str:
    """A self-contained, muted, looping ``<video>`` element holding ``frames`` ``(n, h, w, 3)``."""
    from rlcourse.video import save_mp4

    with tempfile.TemporaryDirectory() as folder:
        data = save_mp4(frames, Path(folder) / "clip.mp4", fps=fps).read_bytes()
    return (f'<video autoplay loop muted playsinline width="{width}" '
            f'src="data:video/mp4;base64,{base64.b64encode(data).decode()}"></video>')


class PreferenceAnnotator:
    """hw3's "be the annotator": two clips side by side, three buttons, then a reward model.

    ``pairs`` ``(n, 2)`` index the segments of ``obs`` ``(N, L, obs_dim)``; each answer is a label
    (1 left better, 1/2 can't tell, 0 right better). After the last answer, ``train(pairs, labels)``
    returns a reward model and ``report(model, labels)`` draws what it learned into the output
    area and returns a line for the status. Both are called when needed, so a function they look up
    by name (a stub filled in after the widget was drawn) is the current one. Every error, a stub's
    included, is shown in the widget; after one, any button tries the failed step again.

    With ``rate`` given, a second phase follows the report (whose line then goes to the output area):
    every clip of ``pairs`` is shown alone, twice, in two shuffled orders (``seed``), and rated on the
    1–10 buttons; after the last rating ``rate(pairs, labels, clips, first, second)`` (``clips`` the
    distinct segments, ``first`` and ``second`` the two ratings of each) returns the status line,
    for instance the test–retest consistency of the ratings against the comparisons. Without
    ``rate`` the widget behaves as it always has.

    Rendering a pair takes seconds, so the next one is rendered in a background thread while the
    current one is on screen: after the first, a click shows the next pair at once. One thread does
    all the rendering (MuJoCo's GL contexts stay in it); an error there is raised, and shown, when
    the click that needs the clip comes.
    """

    CHOICES = (("left is better", 1.0), ("can't tell", 0.5), ("right is better", 0.0))

    def __init__(self, obs: np.ndarray, pairs: np.ndarray, train: Callable[[np.ndarray, np.ndarray], Any],
                 report: Callable[[Any, np.ndarray], str], render: Callable[[np.ndarray], np.ndarray] | None = None,
                 size: int = 128, rate: Callable[..., str] | None = None, seed: int = 0):
        import ipywidgets as widgets

        from rlcourse.preferences import render_segment

        self.obs, self.pairs = obs, np.asarray(pairs)
        self.train, self.report = train, report
        self.render = render or (lambda segment: render_segment(segment, size=size))
        self.labels: list[float] = []
        self.status = widgets.Label()
        self.clip = widgets.HTML()
        self.output = widgets.Output()
        self.buttons = [widgets.Button(description=text) for text, _ in self.CHOICES]
        for button, (_, mu) in zip(self.buttons, self.CHOICES):
            button.on_click(report_errors(self.output, self.status)(functools.partial(self._answer, mu)))
        self.rate = rate
        self.clips = np.unique(self.pairs)
        order = np.random.default_rng(seed)
        self.rating_order = np.concatenate([order.permutation(len(self.clips)), order.permutation(len(self.clips))])
        self.ratings: list[int] = []
        self.scale_buttons = [widgets.Button(description=str(v), layout=widgets.Layout(width="44px"))
                              for v in range(1, 11)]
        for button, value in zip(self.scale_buttons, range(1, 11)):
            button.on_click(report_errors(self.output, self.status)(functools.partial(self._rate, value)))
        self.choice_box, self.scale_box = widgets.HBox(self.buttons), widgets.HBox(self.scale_buttons)
        self.scale_box.layout.display = "none"
        self.box = widgets.VBox([self.status, self.clip, self.choice_box, self.scale_box, self.output])
        self._renderer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="annotator-render")
        self._ahead: dict[tuple[str, int], Future] = {}  # clips rendered, or being rendered, ahead of the click
        self._on_screen = -1  # the pair the buttons answer

    @property
    def n_labels(self) -> int:
        return len(self.pairs)

    def start(self):
        """Render the first pair and return the widget to display."""
        self._show(0)
        return self.box

    def _html(self, kind: str, k: int) -> str:
        """The ``<video>`` of pair ``k`` (``kind`` "pair") or of the ``k``-th clip to rate ("clip")."""
        from rlcourse.video import side_by_side

        shown = self.pairs[k] if kind == "pair" else [self.clips[self.rating_order[k]]]
        return video_html(side_by_side([self.render(self.obs[i]) for i in shown]))

    def _render_ahead(self, kind: str, k: int) -> None:
        """Start rendering ``(kind, k)`` in the background, if it exists and is not under way."""
        if k < (self.n_labels if kind == "pair" else self.n_ratings) and (kind, k) not in self._ahead:
            self._ahead[kind, k] = self._renderer.submit(self._html, kind, k)

    def _take(self, kind: str, k: int) -> str:
        """The clip ``(kind, k)``: rendered ahead if it was (else now), then the next one started."""
        self._render_ahead(kind, k)
        try:
            return self._ahead.pop((kind, k)).result()
        finally:
            self._render_ahead(kind, k + 1)
            if kind == "pair" and k + 1 == self.n_labels and self.rate is not None:
                self._render_ahead("clip", 0)

    def _show(self, k: int) -> None:
        self.clip.value = self._take("pair", k)
        self._on_screen = k
        self.status.value = f"pair {k + 1} of {self.n_labels}: which hops better?"

    def _answer(self, mu: float, _button=None) -> None:
        if len(self.labels) == self._on_screen:  # not after an error, when the click only tries again
            self.labels.append(mu)
        k = len(self.labels)
        if k < self.n_labels:
            with busy(self.status, self.buttons, f"rendering pair {k + 1} of {self.n_labels}..."):
                self._show(k)
            return
        labels = np.array(self.labels, dtype=np.float32)
        self.output.outputs = ()  # an earlier attempt's error or plot
        with busy(self.status, self.buttons, f"training a reward model on your {k} labels..."):
            model = self.train(self.pairs, labels)
            with self.output:  # what report draws (a plot) goes to the widget's output area
                line = self.report(model, labels)
        if self.rate is None:
            self.status.value = line
            return
        self.output.append_stdout(line + "\n")
        self.choice_box.layout.display, self.scale_box.layout.display = "none", None
        with busy(self.status, self.scale_buttons, "rendering the first clip to rate..."):
            self._show_clip(0)

    @property
    def n_ratings(self) -> int:
        return len(self.rating_order)

    def _show_clip(self, k: int) -> None:
        self.clip.value = self._take("clip", k)
        self.status.value = f"clip {k + 1} of {self.n_ratings}: how well does it hop, from 1 (worst) to 10 (best)?"

    def _rate(self, value: int, _button=None) -> None:
        if len(self.ratings) < self.n_ratings:
            self.ratings.append(value)
        k = len(self.ratings)
        if k < self.n_ratings:
            with busy(self.status, self.scale_buttons, f"rendering clip {k + 1} of {self.n_ratings}..."):
                self._show_clip(k)
            return
        n = len(self.clips)
        first, second = np.zeros(n), np.zeros(n)
        first[self.rating_order[:n]] = self.ratings[:n]
        second[self.rating_order[n:]] = self.ratings[n:]
        with busy(self.status, self.scale_buttons, "comparing your ratings with your comparisons..."):
            with self.output:
                self.status.value = self.rate(self.pairs, np.array(self.labels, dtype=np.float32), self.clips,
                                              first, second)
