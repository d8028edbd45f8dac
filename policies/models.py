"""Load a policy network in any of the spec's formats as one function: observation
(float32, (n_obs,)) -> action ((n_act,)), on one CPU thread (on these 2-core machines
small networks ran up to 10x slower multithreaded).

  torchscript   torch.jit.load (legged_gym-style exports, e.g. `policy.pt`)
  torch.export  torch.export.load(...).module() (`.pt2` files)
  onnx          onnxruntime, CPU provider (MuJoCo Playground-style exports)

`load_model` checks the network against the spec's observation and action sizes and
names the mismatch. A recurrent torch policy keeps its memory in buffers (legged_gym's
LSTM exports do: the G1's `motion.pt` holds hidden and cell states); `Model.reset`
restores every buffer to its value in the file, so each episode starts as the first.
"""

from __future__ import annotations

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
        with torch.inference_mode():
            out = module(torch.from_numpy(obs[None]))
        if isinstance(out, (tuple, list)):
            out = out[0]
        return out.detach().numpy().reshape(-1).astype(np.float64)

    def reset() -> None:
        with torch.no_grad():
            for k, v in module.named_buffers():
                v.copy_(buffers[k])

    return Model(run, reset)


def load_model(path, fmt: str, n_obs: int, n_act: int, where: str = "policy") -> Model:
    if fmt in ("torchscript", "torch.export"):
        import torch

        import warnings

        torch.set_num_threads(1)
        try:
            with warnings.catch_warnings():  # torch 2.13 marks TorchScript deprecated; published policies use it
                warnings.simplefilter("ignore", DeprecationWarning)
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
        inp = session.get_inputs()
        if len(inp) != 1:
            raise ConfigError(f"{where}: the ONNX model takes {len(inp)} inputs ({[i.name for i in inp]}); the runner "
                              "feeds one observation vector")
        name = inp[0].name
        shape = inp[0].shape
        if isinstance(shape[-1], int) and shape[-1] != n_obs:
            raise ConfigError(f"{where}: the ONNX model takes {shape[-1]} observation values; the spec's observation "
                              f"terms give {n_obs}")

        model = Model(lambda obs: np.asarray(session.run(None, {name: obs[None]})[0], dtype=np.float64).reshape(-1))
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
