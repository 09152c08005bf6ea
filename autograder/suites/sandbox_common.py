"""Helpers every hidden suite may call in the sandbox: ``student.helpers.<name>(...)`` and ``reference.helpers``.

The grader runs this file in the sandbox, beside the submission, before the suite's own
``sandbox_helpers.py``, into the same module, so a suite's helpers may use these names. ``notebook`` is
the namespace of the submission (or of the reference, on the reference's side), set by the worker.

Student code can read and patch everything here (and the torch and numpy it runs on), so these helpers
only build objects and gather raw data: values, gradients, weights, the inputs as a call left them. Each
test judges that data on the grader's side, against a closed form or the reference; nothing here returns
a verdict ("it raised", "it was called three times", "it needs a gradient"), since a submission could
choose the verdict. Given classes are imported from the release by their full path, never looked up in
the notebook, where a submission may have bound its own object to the name.
"""
import importlib
from contextlib import contextmanager

import torch

_ABSENT = object()


def build(path: str, *args, torch_seed=None, **kwargs):
    """An instance of the released class ``path`` (``"rlcourse.nets.GaussianPolicy"``), built with ``args``
    and ``kwargs``, its weights drawn under ``torch.manual_seed(torch_seed)`` when that is given."""
    module, _, name = path.rpartition(".")
    if module.split(".")[0] != "rlcourse":
        raise ValueError(f"build() makes the release's own classes only (rlcourse.*), not {path!r}")
    cls = getattr(importlib.import_module(module), name)
    if torch_seed is not None:
        torch.manual_seed(torch_seed)
    return cls(*args, **kwargs)


def module_state(module) -> dict:
    """The tensors of ``module.state_dict()``, detached copies (the grader loads them into its own copy)."""
    return {key: value.detach().clone() for key, value in module.state_dict().items()}


def _leaf(value):
    """A fresh leaf that requires a gradient: a float tensor copy of ``value``."""
    tensor = torch.as_tensor(value)
    if not tensor.is_floating_point():
        tensor = tensor.double()
    return tensor.detach().clone().requires_grad_(True)


def _with_leaves(args, kwargs, wrt):
    """``args`` and ``kwargs`` with the entries named by ``wrt`` (positions or keyword names) made leaves."""
    args, kwargs, leaves = list(args), dict(kwargs or {}), []
    for key in wrt:
        if isinstance(key, int):
            args[key] = _leaf(args[key])
            leaves.append(args[key])
        else:
            kwargs[key] = _leaf(kwargs[key])
            leaves.append(kwargs[key])
    return args, kwargs, leaves


def _pick(out, output):
    """``out`` itself (``output`` None), ``out[output]``, or, for a list of keys, ``out[k0][k1]...``."""
    if output is None:
        return out
    for key in (output if isinstance(output, (list, tuple)) else [output]):
        out = out[key]
    return out


def _differentiate(value, inputs, grad_outputs=None):
    """d value / d each input (``None`` where the value does not depend on it, or carries no autograd graph);
    for a value that is not a scalar, the vector-Jacobian product with ``grad_outputs`` (of the value's shape)."""
    if not (isinstance(value, torch.Tensor) and value.requires_grad):
        return [None] * len(inputs)
    if grad_outputs is not None:
        grad_outputs = torch.as_tensor(grad_outputs, dtype=value.dtype)
    return list(torch.autograd.grad(value, inputs, grad_outputs=grad_outputs, allow_unused=True))


def value_and_grad(stub: str, args, kwargs=None, wrt=(0,), output=None, grad_outputs=None):
    """``(out, grads)``: ``out = notebook[stub](*args, **kwargs)`` with the arguments that ``wrt`` names
    (positions in ``args``, names in ``kwargs``) made fresh leaves, and the gradients of ``out`` (of
    ``out[output]``, or ``out[k0][k1]`` for a list of keys; weighted by ``grad_outputs`` when it is not a scalar) with
    respect to each of them, ``None`` where none flows."""
    args, kwargs, leaves = _with_leaves(args, kwargs, wrt)
    out = notebook[stub](*args, **kwargs)  # noqa: F821 - set by the worker
    return out, _differentiate(_pick(out, output), leaves, grad_outputs)


def grad(stub: str, args, kwargs=None, wrt=(0,), output=None, grad_outputs=None):
    """The gradients of :func:`value_and_grad`, alone."""
    return value_and_grad(stub, args, kwargs, wrt, output, grad_outputs)[1]


def parameter_grads(stub: str, args, kwargs=None, module=0, output=None, names=None, grad_outputs=None):
    """``(out, grads)``: ``out = notebook[stub](*args, **kwargs)`` and the gradient of ``out`` (or of
    ``out[output]``; weighted by ``grad_outputs`` when it is not a scalar) with respect to each parameter
    of the network ``args[module]``, as a dict from the parameter's name (only those in ``names`` when
    given) to its gradient, ``None`` where none flows."""
    params = dict(args[module].named_parameters())
    chosen = list(params) if names is None else list(names)
    out = notebook[stub](*args, **(kwargs or {}))  # noqa: F821 - set by the worker
    grads = _differentiate(_pick(out, output), [params[n] for n in chosen], grad_outputs)
    return out, dict(zip(chosen, grads))


def call_and_inputs(stub: str, args, kwargs=None):
    """``(out, args, kwargs)``: what ``notebook[stub](*args, **kwargs)`` returned, and its arguments as the
    call left them (a test compares them with what it sent, to see that nothing was modified in place)."""
    args, kwargs = list(args), dict(kwargs or {})
    out = notebook[stub](*args, **kwargs)  # noqa: F821 - set by the worker
    return out, args, kwargs


@contextmanager
def standing_in(**functions):
    """The notebook's functions of these names replaced by ``functions`` for the duration, then put back (or removed
    again where the notebook defined none). A suite's own stand-in for a stub that the grader's reference cannot
    replace, because it is called with a network or a tensor that needs gradients (which cannot cross), so that a
    mistake in that stub costs it alone, not the stubs that call it."""
    saved = {name: notebook.get(name, _ABSENT) for name in functions}  # noqa: F821 - set by the worker
    notebook.update(functions)  # noqa: F821
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is _ABSENT:
                notebook.pop(name, None)  # noqa: F821
            else:
                notebook[name] = value  # noqa: F821
