"""Load a policy network in any of the spec's formats as one function: observation
(float32, (n_obs,)) -> action ((n_act,)), on one CPU thread (on these 2-core machines
small networks ran up to 10x slower multithreaded).

  torchscript   torch.jit.load (legged_gym-style exports, e.g. `policy.pt`)
  torch.export  torch.export.load(...).module() (`.pt2` files)
  onnx          onnxruntime, CPU provider (MuJoCo Playground-style exports; a recurrent
                export's state inputs fed back from its outputs, zeros at reset)

`load_model` checks the network against the spec's observation and action sizes and
names the mismatch. A recurrent torch policy keeps its memory in buffers (legged_gym's
LSTM exports do: the G1's `motion.pt` holds hidden and cell states); `Model.reset`
restores every buffer to its value in the file, so each episode starts as the first.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from typing import Callable

import numpy as np

from legcal_bench.errors import ConfigError


class Model:
    """A loaded policy network: `model(obs)` -> action; `reset()` clears its memory."""

    def __init__(self, run: Callable[[np.ndarray], np.ndarray], reset: Callable[[], None] = lambda: None):
        self._run, self.reset = run, reset

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self._run(obs)


def _torch(module) -> Model:
    import torch

    buffers = {k: v.detach().clone() for k, v in module.named_buffers()}

    def run(obs: np.ndarray) -> np.ndarray:
        with torch.inference_mode():  # (an LSTM's kernels differ outside it)
            out = module(torch.from_numpy(obs[None]))
        if isinstance(out, (tuple, list)):
            out = out[0]
        return out.detach().numpy().reshape(-1).astype(np.float64)

    def reset() -> None:
        with torch.no_grad():
            for k, v in module.named_buffers():
                v.copy_(buffers[k])

    return Model(_eager_mlp(module, run) or run, reset)


# Layers an eager replica knows: (type name, the function of its input).
_EAGER_LAYERS = {"Linear": lambda F, m: lambda x, w=m.weight.detach(), b=None if m.bias is None else m.bias.detach():
                 F.linear(x, w, b),
                 "ELU": lambda F, m: lambda x, a=float(getattr(m, "alpha", 1.0)): F.elu(x, a),
                 "ReLU": lambda F, m: F.relu, "Tanh": lambda F, m: lambda x: x.tanh(), "Identity": lambda F, m: None}
EAGER_PROBES = 64  # random observations an eager replica must answer bit for bit as the file's module does


def _eager_mlp(module, run: Callable[[np.ndarray], np.ndarray]) -> Callable[[np.ndarray], np.ndarray] | None:
    """The same network run layer by layer from Python, where the file's module is an MLP
    (a Sequential of `_EAGER_LAYERS`, alone or as `mlp` after a `(obs - mean) / std`
    normalization, no other state): the same kernels without the TorchScript
    interpreter's per-call cost (a tenth of a walk's step). Used only if it gives every
    probe observation's action bit for bit; None otherwise (the module runs as it is)."""
    import torch
    import torch.nn.functional as F

    kind = lambda m: getattr(m, "original_name", type(m).__name__)  # noqa: E731  (scripted modules keep it)
    children = dict(module.named_children())
    buffers = dict(module.named_buffers(recurse=False))
    seq, norm = module, None
    if set(children) == {"mlp"} and set(buffers) == {"mean", "std"}:
        seq, norm = children["mlp"], (buffers["mean"].detach(), buffers["std"].detach())
    elif buffers:
        return None
    layers = list(seq.named_children())
    if not layers or kind(seq) != "Sequential" or any(kind(m) not in _EAGER_LAYERS or any(m.named_buffers())
                                                     for _, m in layers):
        return None
    fns = [f for f in (_EAGER_LAYERS[kind(m)](F, m) for _, m in layers) if f is not None]
    first = layers[0][1]
    if kind(first) != "Linear":
        return None

    def eager(obs: np.ndarray) -> np.ndarray:
        x = torch.from_numpy(obs[None])
        if norm is not None:
            x = (x - norm[0]) / norm[1]
        for f in fns:
            x = f(x)
        return x.numpy().reshape(-1).astype(np.float64)

    rng = np.random.default_rng(0)
    probes = rng.standard_normal((EAGER_PROBES, first.weight.shape[1])) * rng.choice([0.01, 1.0, 100.0], (EAGER_PROBES, 1))
    try:
        same = all(np.array_equal(run(x), eager(x)) for x in probes.astype(np.float32))
    except Exception:  # noqa: BLE001  (a layer the replica misreads: the module runs as it is)
        return None
    return eager if same else None


def _onnx(session, n_obs: int, where: str) -> Model:
    """An ONNX policy: one input is the observation (the one named `obs`, else the one of
    `n_obs` values); a recurrent export's other inputs are its state, fed back from the
    outputs after the action (the first output), paired in order and shape (`h_in` ->
    `h_out`, ...), zeros at reset."""
    inputs, outputs = session.get_inputs(), session.get_outputs()
    named = [i for i in inputs if i.name == "obs"]
    sized = [i for i in inputs if isinstance(i.shape[-1], int) and i.shape[-1] == n_obs]
    obs_in = named[0] if named else (sized[0] if len(sized) == 1 else inputs[0])
    shape = obs_in.shape
    if isinstance(shape[-1], int) and shape[-1] != n_obs:
        raise ConfigError(f"{where}: the ONNX model takes {shape[-1]} observation values; the spec's observation "
                          f"terms give {n_obs}")
    states = [i for i in inputs if i is not obs_in]
    if len(outputs) < 1 + len(states):
        raise ConfigError(f"{where}: the ONNX model has state inputs {[i.name for i in states]} but "
                          f"{len(outputs) - 1} outputs after the action to feed them back: a recurrent policy "
                          "returns its next state after the action, one output per state input, in order")

    def concrete(shape) -> tuple:
        return tuple(d if isinstance(d, int) else 1 for d in shape)

    for i, o in zip(states, outputs[1:]):
        if concrete(i.shape) != concrete(o.shape):
            raise ConfigError(f"{where}: ONNX state input {i.name} {i.shape} and output {o.name} {o.shape} differ: "
                              "the state outputs must follow the action in the order of the state inputs")
    types = {"tensor(float)": np.float32, "tensor(double)": np.float64}
    zero = {i.name: np.zeros(concrete(i.shape), dtype=types.get(i.type, np.float32)) for i in states}
    state = dict(zero)
    names = [o.name for o in outputs[:1 + len(states)]]

    def run(obs: np.ndarray) -> np.ndarray:
        out = session.run(names, {obs_in.name: obs[None], **state})
        for i, value in zip(states, out[1:]):
            state[i.name] = value
        return np.asarray(out[0], dtype=np.float64).reshape(-1)

    def reset() -> None:
        state.update(zero)

    return Model(run, reset)


@contextmanager
def _quiet(logger: str):
    """Silence a library's logger below ERROR for the block: torch.export logs a whole
    traceback as a warning before raising on a file it cannot read, which the one-line
    ConfigError then says better."""
    log = logging.getLogger(logger)
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


def load_model(path, fmt: str, n_obs: int, n_act: int, where: str = "policy") -> Model:
    if fmt in ("torchscript", "torch.export"):
        import torch

        import warnings

        torch.set_num_threads(1)
        try:
            with warnings.catch_warnings(), _quiet("torch.export"):
                warnings.simplefilter("ignore", DeprecationWarning)  # torch 2.13: TorchScript deprecated
                module = torch.jit.load(str(path), map_location="cpu") if fmt == "torchscript" else \
                torch.export.load(str(path)).module()
        except Exception as e:  # a file of another format fails here
            raise ConfigError(f"{where}: {path} is not a {fmt} model ({type(e).__name__}: {e}); check model.format") \
                from None
        if fmt == "torchscript":
            module.eval()
        model = _torch(module)
    elif fmt == "onnx":
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = opts.inter_op_num_threads = 1
        try:
            session = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
        except Exception as e:
            raise ConfigError(f"{where}: {path} is not an ONNX model ({type(e).__name__}); check model.format") \
                from None
        model = _onnx(session, n_obs, where)
    else:
        raise ConfigError(f"{where}: model.format {fmt!r}: use torchscript, torch.export or onnx")
    try:
        out = model(np.zeros(n_obs, dtype=np.float32))
    except Exception as e:
        raise ConfigError(f"{where}: the model does not accept {n_obs} observation values (the spec's terms): "
                          f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}") from None
    if out.shape != (n_act,):
        raise ConfigError(f"{where}: the model outputs {out.size} values; the spec's joints need {n_act}")
    model.reset()
    return model
