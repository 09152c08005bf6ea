"""rlcourse.widgets without a browser: errors reach the widget's output area, progress shows, answers advance.

Buttons are clicked with ``Button.click()``, which runs the same handlers a click in JupyterLab runs;
tests/test_browser.py clicks the real widget in Chromium.
"""
import numpy as np
import pytest

widgets = pytest.importorskip("ipywidgets")

from rlcourse.widgets import PreferenceAnnotator, explain, report_errors, video_html  # noqa: E402


def train_reward_model(*args):
    raise NotImplementedError()


def segment_return(x):
    return np.ones(3) @ np.ones(x)  # a shape error inside numpy


def stderr_text(output) -> str:
    return "".join(o["text"] for o in output.outputs if o.get("name") == "stderr")


def test_explain_names_the_unfinished_stub_and_the_failing_function():
    with pytest.raises(NotImplementedError) as err:
        train_reward_model()
    assert explain(err.value).startswith("`train_reward_model` is not implemented yet")
    with pytest.raises(ValueError) as err:
        segment_return(4)
    message = explain(err.value)
    assert message.startswith("`segment_return` raised ValueError: "), message  # the student's frame, not numpy's


def test_report_errors_writes_the_error_into_the_output_area_and_swallows_it():
    output, status, calls = widgets.Output(), widgets.Label(value="working"), []
    guarded = report_errors(output, status, on_error=lambda: calls.append("cleanup"))(train_reward_model)
    assert guarded() is None  # nothing escapes to JupyterLab's log console
    assert stderr_text(output) == "`train_reward_model` is not implemented yet: fill in its cell, run it, then click again.\n"
    assert status.value.startswith("stopped") and calls == ["cleanup"]
    output.outputs = ()
    report_errors(output)(segment_return)(4)
    text = stderr_text(output)
    assert text.startswith("`segment_return` raised ValueError: ") and "Traceback" in text  # then where it failed
    assert report_errors(output)(lambda a: a + 1)(1) == 2


def test_video_html_is_a_self_contained_muted_video():
    html = video_html(np.zeros((4, 16, 32, 3), dtype=np.uint8), fps=4)
    assert html.startswith("<video autoplay loop muted") and 'src="data:video/mp4;base64,' in html


def test_annotator_renders_the_next_pair_ahead_and_reports_an_unfinished_stub_in_place():
    import threading

    rendered = []  # (segment, thread, clicks so far) of every render

    def render(segment):
        rendered.append((int(segment[0, 0]), threading.current_thread().name, len(annotator.labels)))
        return np.zeros((3, 16, 16, 3), dtype=np.uint8)

    trained = []

    def train(pairs, labels):
        if not trained:
            return train_reward_model(pairs, labels)  # the stub, still unfinished
        return "model"

    def report(model, labels):
        return f"done with {model} on {labels.tolist()}"

    obs = np.arange(6, dtype=np.float32)[:, None, None] * np.ones((6, 3, 11), dtype=np.float32)  # segment i holds i
    annotator = PreferenceAnnotator(obs, np.array([[0, 1], [2, 3], [4, 5]]), train, report, render=render)
    annotator.start()
    assert annotator.status.value == "pair 1 of 3: which hops better?" and "<video" in annotator.clip.value
    annotator._ahead["pair", 1].result()  # pair 2 is rendered while pair 1 is on screen, before any click
    assert [(s, clicks) for s, _, clicks in rendered] == [(0, 0), (1, 0), (2, 0), (3, 0)], rendered
    left, tie, right = annotator.buttons
    left.click()
    assert annotator.status.value == "pair 2 of 3: which hops better?"
    assert not any(b.disabled for b in annotator.buttons)
    tie.click()
    right.click()  # the last answer: train_reward_model raises
    assert annotator.labels == [1.0, 0.5, 0.0]
    assert {thread for _, thread, _ in rendered} == {"annotator-render_0"}, rendered  # one thread renders all
    assert sorted(s for s, _, _ in rendered) == [0, 1, 2, 3, 4, 5]  # each pair once
    assert stderr_text(annotator.output).startswith("`train_reward_model` is not implemented yet")
    assert annotator.status.value.startswith("stopped") and not any(b.disabled for b in annotator.buttons)
    trained.append(True)  # the student fills the stub in and clicks again
    left.click()
    assert annotator.labels == [1.0, 0.5, 0.0] and annotator.output.outputs == ()
    assert annotator.status.value == "done with model on [1.0, 0.5, 0.0]"


def test_annotator_shows_an_error_from_the_background_render_on_the_click_that_needs_it():
    calls = []

    def render(segment):
        calls.append(int(segment[0, 0]))
        if int(segment[0, 0]) == 2 and calls.count(2) == 1:
            raise RuntimeError("no GL context")
        return np.zeros((3, 16, 16, 3), dtype=np.uint8)

    obs = np.arange(4, dtype=np.float32)[:, None, None] * np.ones((4, 3, 11), dtype=np.float32)
    annotator = PreferenceAnnotator(obs, np.array([[0, 1], [2, 3]]), lambda p, l: None, lambda m, l: "done",
                                    render=render)
    annotator.start()
    annotator.buttons[0].click()
    assert "RuntimeError: no GL context" in stderr_text(annotator.output)
    assert annotator.status.value.startswith("stopped") and not any(b.disabled for b in annotator.buttons)
    annotator.output.outputs = ()
    annotator.buttons[0].click()  # tried again: rendered now
    assert annotator.status.value == "pair 2 of 2: which hops better?" and annotator.labels == [1.0]
