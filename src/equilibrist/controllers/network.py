"""``--controller policy --policy FILE``: a trained network (an MLP) as a controller.

The file is a Stable-Baselines3 model (``.zip``: PPO's or A2C's actor, or SAC's
squashed Gaussian mean) or a PyTorch state dict of an ``nn.Sequential`` of
``Linear`` layers with one activation between them (``.pt``/``.pth``;
``--activation tanh|relu``, tanh by default). It is read with PyTorch (the
``rl`` extra) and becomes a :class:`~equilibrist.control.nonlinear.NonlinearController`
whose source is the network's forward pass in the subset that
:mod:`equilibrist.native.pyc` translates: every layer's units are scalars of
the source (the subset has no local arrays: nothing is allocated), the weights
are the controller's parameters, and ``tanh`` is computed from the project's
own ``eq_exp`` (:mod:`equilibrist.numeric.libm`: no C library function). So the
simulation's compiled core, the C export (its vectors replayed by ``make
check``, ``make size``) and hardware in the loop all run the same arithmetic,
and the Python runtime gives the same bits as the C.

The network reads what an agent of an ``-v1`` environment sees (the whole state,
:func:`observation_map`: each state's deviation from the operating point in
Bryson scales; in the swing-up the hanging angles' cosines and sines) and
answers an action in ``[-1, 1]`` (clipped, or through ``tanh`` for SAC), mapped
onto the input's limits as the environments map it. Which task's observation
it reads follows from its input size.
"""

from __future__ import annotations

import io
import json
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.controllers.kinds import ControllerKind, ControllerRequest, KindError, Option
from equilibrist.errors import quote_outside

if TYPE_CHECKING:
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.numeric.system import System
    from equilibrist.tasks import Task

ACTIVATIONS = ("tanh", "relu")


@dataclass(frozen=True)
class ObservationMap:
    """An agent's observation of the states: component ``i`` of the observed states is
    ``(x - offset) * gain``, or where ``trig`` its ``cos, sin`` about ``offset``."""

    names: tuple[str, ...]
    offset: np.ndarray
    gain: np.ndarray
    trig: np.ndarray

    @property
    def size(self) -> int:
        return len(self.names)


def observation_map(system: System, task: Task, observed: tuple[str, ...]) -> ObservationMap:
    """The ``-v1`` observation of the states *observed* of *system* in *task*: deviations from
    the task's operating point in its Bryson scales, a hanging angle of the swing-up as its
    cosine and sine (the one definition the environments and the policies read)."""
    names = system.state_names
    trig_coords = set(system.spec.hanging or {}) if task.name == "swingup" else set()
    idx = [names.index(o) for o in observed]
    labels: list[str] = []
    for o in observed:
        labels += [f"cos({o})", f"sin({o})"] if o in trig_coords else [o]
    scales = np.asarray(task.state_scales, dtype=float)
    return ObservationMap(
        names=tuple(labels), offset=np.asarray(task.x_op, dtype=float)[idx],
        gain=1.0 / scales[idx],
        trig=np.array([o in trig_coords for o in observed], dtype=bool))


@dataclass(frozen=True)
class Network:
    """An MLP: ``weights[k]`` is ``(out, in)``, ``biases[k]`` ``(out,)``; *activation* between
    layers; the output through ``tanh`` when *squash*, else clipped to ``[-1, 1]``."""

    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    activation: str
    squash: bool

    @property
    def n_in(self) -> int:
        return int(self.weights[0].shape[1])

    @property
    def n_out(self) -> int:
        return int(self.weights[-1].shape[0])

    def forward(self, obs: np.ndarray) -> np.ndarray:
        """The action of *obs* in numpy (float64; a reference, not the controller's path)."""
        h = np.asarray(obs, dtype=float)
        for k, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = w @ h + b
            if k < len(self.weights) - 1:
                h = np.tanh(h) if self.activation == "tanh" else np.maximum(h, 0.0)
        out: np.ndarray = np.tanh(h) if self.squash else np.clip(h, -1.0, 1.0)
        return out


def _torch_load(data: bytes, what: str) -> dict[str, np.ndarray]:
    try:
        import torch
    except ImportError:
        raise KindError("--controller policy reads networks with PyTorch: "
                        "pip install 'equilibrist[rl]'") from None
    try:
        state = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except Exception as exc:  # any failure to read is the file's
        raise KindError(f"--policy {what}: not a PyTorch state dict "
                        f"({quote_outside(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)})"
                        ) from None
    if not isinstance(state, dict):
        raise KindError(f"--policy {what}: expected a state dict (names -> tensors), got "
                        f"{type(state).__name__}")
    return {str(k): v.detach().double().numpy() for k, v in state.items()
            if hasattr(v, "detach")}


def _layers(state: dict[str, np.ndarray], prefix: str, what: str
            ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The ``Linear`` layers ``<prefix><k>.weight`` in the order of ``k``."""
    found = sorted((int(m.group(1)), key) for key in state
                   if (m := re.fullmatch(re.escape(prefix) + r"(\d+)\.weight", key)))
    weights, biases = [], []
    for _, key in found:
        w = state[key]
        b = state.get(key[: -len("weight")] + "bias")
        if w.ndim != 2 or b is None or b.shape != (w.shape[0],):
            raise KindError(f"--policy {what}: {key} is not a Linear layer's weight with its bias")
        weights.append(w)
        biases.append(b)
    return weights, biases


def read_network(path: str | Path, *, activation: str | None = None) -> Network:
    """The MLP in *path* (see the module), checked to be a chain of layers."""
    p = Path(path)
    what = quote_outside(str(p))
    if not p.is_file():
        raise KindError(f"--policy {what}: no such file (expected a Stable-Baselines3 .zip or "
                        "a PyTorch state dict)")
    raw = p.read_bytes()
    if _is_sb3(raw):
        net = _sb3_network(raw, what)
    else:
        state = _torch_load(raw, what)
        weights, biases = _layers(state, "", what)
        if not weights:
            raise KindError(f"--policy {what}: no Linear layers named 0.weight, 2.weight... "
                            "(an nn.Sequential's state dict)")
        net = Network(tuple(weights), tuple(biases), activation or "tanh", False)
    if activation is not None and activation != net.activation:
        net = Network(net.weights, net.biases, activation, net.squash)
    for k in range(1, len(net.weights)):
        if net.weights[k].shape[1] != net.weights[k - 1].shape[0]:
            raise KindError(f"--policy {what}: layer {k} takes {net.weights[k].shape[1]} inputs, "
                            f"layer {k - 1} gives {net.weights[k - 1].shape[0]}")
    return net


def _is_sb3(raw: bytes) -> bool:
    """Whether *raw* is a Stable-Baselines3 archive (a zip holding ``policy.pth``; PyTorch's
    own files are zips too, holding ``<name>/data.pkl``)."""
    if not zipfile.is_zipfile(io.BytesIO(raw)):
        return False
    with zipfile.ZipFile(io.BytesIO(raw)) as zf:
        return "policy.pth" in zf.namelist()


def _sb3_network(raw: bytes, what: str) -> Network:
    """The deterministic actor of a Stable-Baselines3 model's archive."""
    with zipfile.ZipFile(io.BytesIO(raw)) as zf:
        names = zf.namelist()
        state = _torch_load(zf.read("policy.pth"), what)
        data = json.loads(zf.read("data")) if "data" in names else {}
    kwargs = data.get("policy_kwargs") if isinstance(data, dict) else None
    act_text = str(kwargs.get("activation_fn", "")) if isinstance(kwargs, dict) else ""
    if "action_net.weight" in state:  # PPO, A2C: the Gaussian's mean, clipped
        weights, biases = _layers(state, "mlp_extractor.policy_net.", what)
        weights.append(state["action_net.weight"])
        biases.append(state["action_net.bias"])
        activation, squash = ("relu" if "ReLU" in act_text else "tanh"), False
    elif "actor.mu.weight" in state:  # SAC: tanh of the Gaussian's mean
        weights, biases = _layers(state, "actor.latent_pi.", what)
        weights.append(state["actor.mu.weight"])
        biases.append(state["actor.mu.bias"])
        activation, squash = ("tanh" if "Tanh" in act_text else "relu"), True
    else:
        raise KindError(f"--policy {what}: a Stable-Baselines3 model of neither PPO/A2C "
                        "(action_net) nor SAC (actor.mu)")
    return Network(tuple(weights), tuple(biases), activation, squash)


def _fmt(k: int) -> str:
    return f"params[{k}]"


def network_source(net: Network, obs: ObservationMap, n_inputs: int) -> tuple[str, np.ndarray]:
    """The controller's source (the forward pass) and its parameters: ``[offset | gain | each
    layer's rows (weights then bias) | input lows | highs]``.

    The subset has no local arrays, so the units of every hidden layer but the last are
    scalars of the source (one line each); the last hidden layer is a loop over its units
    whose each unit is added, weighted, into the outputs' sums at once (the code grows
    with the first layers' sizes, not with the last's square)."""
    params: list[float] = [*obs.offset.tolist(), *obs.gain.tolist()]
    n_y = obs.offset.shape[0]
    lines = ["def output(t, z, y, r, params, u_out):"]
    inputs: list[str] = []
    for i in range(n_y):
        if obs.trig[i]:
            lines += [f"    x{len(inputs)} = eq_cos(y[{i}] - {_fmt(i)})",
                      f"    x{len(inputs) + 1} = eq_sin(y[{i}] - {_fmt(i)})"]
            inputs += [f"x{len(inputs)}", f"x{len(inputs) + 1}"]
        else:
            lines.append(f"    x{len(inputs)} = (y[{i}] - {_fmt(i)}) * {_fmt(n_y + i)}")
            inputs.append(f"x{len(inputs)}")
    layers = list(zip(net.weights, net.biases, strict=True))
    for k, (w, b) in enumerate(layers[:-2]):
        names = []
        for j in range(w.shape[0]):
            base = len(params)
            params += [*w[j].tolist(), float(b[j])]
            terms = "".join(f" + {_fmt(base + i)} * {v}" for i, v in enumerate(inputs))
            lines.append(f"    h{k}_{j} = nn_{net.activation}({_fmt(base + w.shape[1])}{terms})")
            names.append(f"h{k}_{j}")
        inputs = names
    w_out, b_out = layers[-1]
    outs = [f"a{i}" for i in range(w_out.shape[0])]
    if len(layers) >= 2:
        w, b = layers[-2]
        base, stride = len(params), w.shape[1] + 1 + w_out.shape[0]
        for j in range(w.shape[0]):  # row j: its weights, its bias, its unit's output weights
            params += [*w[j].tolist(), float(b[j]), *w_out[:, j].tolist()]
        o_bias = len(params)
        params += b_out.tolist()
        lines += [f"    {a} = {_fmt(o_bias + i)}" for i, a in enumerate(outs)]
        terms = "".join(f" + params[row + {i}] * {v}" for i, v in enumerate(inputs))
        lines += [f"    for j in range({w.shape[0]}):",
                  f"        row = {base} + j * {stride}",
                  f"        h = nn_{net.activation}(params[row + {w.shape[1]}]{terms})"]
        lines += [f"        {a} = {a} + params[row + {w.shape[1] + 1 + i}] * h"
                  for i, a in enumerate(outs)]
    else:
        for i, a in enumerate(outs):
            base = len(params)
            params += [*w_out[i].tolist(), float(b_out[i])]
            terms = "".join(f" + {_fmt(base + q)} * {v}" for q, v in enumerate(inputs))
            lines.append(f"    {a} = {_fmt(base + w_out.shape[1])}{terms}")
    squash = "nn_tanh" if net.squash else "nn_clip"
    lo = len(params)
    for i, a in enumerate(outs[:n_inputs]):
        lines.append(f"    u_out[{i}] = {_fmt(lo + i)} + 0.5 * ({squash}({a}) + 1.0) * "
                     f"({_fmt(lo + n_inputs + i)} - {_fmt(lo + i)})")
    source = "\n".join([_HELPERS, *lines, "", "", _UPDATE])
    return source, np.asarray(params, dtype=float)


_HELPERS = '''
def nn_tanh(v):
    """tanh from eq_exp: (1 - e) / (1 + e) with e = exp(-2 |v|), then v's sign."""
    a = v
    if a < 0.0:
        a = -a
    e = eq_exp(-2.0 * a)
    s = (1.0 - e) / (1.0 + e)
    if v < 0.0:
        return -s
    return s


def nn_relu(v):
    if v > 0.0:
        return v
    return 0.0


def nn_clip(v):
    if v > 1.0:
        return 1.0
    if v < -1.0:
        return -1.0
    return v

'''

_UPDATE = '''def update(t, z, y, r, u_applied, params, z_out):
    return
'''


def network_controller(system: System, net: Network, *, rate: float, what: str = "the network"
                       ) -> NonlinearController:
    """*net* acting on *system* at *rate* through the ``-v1`` observation of its whole state
    (the balance's or the swing-up's, by the network's input size)."""
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.tasks import get_task, task_names

    states = tuple(system.state_names)
    maps = {task: observation_map(system, get_task(system, task), states)
            for task in task_names(system)}
    fits = [task for task, m in maps.items() if m.size == net.n_in]
    if not fits or net.n_out != system.n_inputs:
        sizes = ", ".join(f"{m.size} ({task})" for task, m in maps.items())
        raise KindError(f"{what} takes {net.n_in} observation(s) and gives {net.n_out} "
                        f"action(s); {system.key}'s -v1 observations have {sizes or 'none'} "
                        f"and it has {system.n_inputs} input(s)")
    task = fits[0]
    source, params = network_source(net, maps[task], system.n_inputs)
    lo, hi = system.input_limits
    params = np.concatenate([params, np.asarray(lo, float), np.asarray(hi, float)])
    t = get_task(system, task)
    widths = [int(w.shape[0]) for w in net.weights]
    return NonlinearController(
        name="policy", source=source, params=params, z0=np.zeros(0), rate=float(rate),
        x_op=np.asarray(t.x_op, float), u_op=np.asarray(t.u_op, float), state_names=states,
        input_names=system.input_names, output_names=states,
        settings={"task": task, "layers": [net.n_in, *widths], "activation": net.activation,
                  "output": "tanh" if net.squash else "clip"})


def build(request: ControllerRequest) -> NonlinearController:
    path = request.options.get("policy")
    if path is None:
        raise KindError("--controller policy needs --policy FILE (a Stable-Baselines3 .zip or a "
                        "PyTorch state dict)")
    net = read_network(str(path), activation=request.options.get("activation"))
    return network_controller(request.system, net, rate=request.sample_rate,
                              what=f"--policy {quote_outside(str(path))}")


KIND = ControllerKind(
    name="policy", label="Trained policy (MLP)",
    help="a trained network acting on the scaled state (--policy FILE: a Stable-Baselines3 "
         ".zip or a PyTorch state dict)",
    build=build,
    options=(Option("--policy", "the trained network of --controller policy", metavar="FILE",
                    expected="a file"),
             Option("--activation", "a PyTorch state dict's activation (default tanh)",
                    choices=ACTIVATIONS)),
    surfaces=frozenset({"simulate", "export", "study"}), noise="spec", order=80,
)


__all__ = ["KIND", "Network", "ObservationMap", "network_controller", "network_source",
           "observation_map", "read_network"]
