"""Reading checkpoints safely: what makes a file loadable, and the error when it is not.

A Stable-Baselines3 archive (``.zip``) holds a ``data`` JSON whose ``":serialized:"`` entries
are cloudpickle payloads, and ``.pth`` files of tensors. Nothing a file supplies is unpickled
here: :func:`read_sb3_archive` parses the JSON itself and rebuilds every serialized entry from
what is known (the expected classes, the spaces described by the JSON's plain fields or by an
environment, constant schedules, the Lagrange multiplier's plain fields, empty statistics
windows), refusing any entry it does not know; the ``.pth`` files are read with
``torch.load(weights_only=True)`` and every tensor must be finite. The rebuilt entries are
then handed to Stable-Baselines3 as ``custom_objects``, which it uses instead of deserialising
those keys.

A class entry (``policy_class``, ``replay_buffer_class``) is read as a name only: its pickle
must be a bare reference ``module.name`` (its opcodes are parsed, never run), and the class is
taken from an already imported module and must subclass the expected base class.
"""
from __future__ import annotations

import collections
import io
import json
import math
import pathlib
import pickletools
import re
import sys
import zipfile
import zlib
from base64 import b64decode
from binascii import Error as Base64Error
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, FrozenSet, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import torch as th

PathLike = Union[str, pathlib.Path, io.BufferedIOBase]


class CheckpointError(ValueError):
    """A checkpoint that cannot be loaded: corrupt, truncated, incomplete, unsafe or for another setup."""


# ---------------------------------------------------------------------- bytes and zip integrity
def read_file_bytes(path: PathLike, suffix: str = ".zip") -> Tuple[str, bytes]:
    """``(name, content)`` of ``path`` (a file, or a stream read to its end); a missing file raises
    ``FileNotFoundError`` (``path`` without ``suffix`` is tried with it, as Stable-Baselines3 does)."""
    if isinstance(path, (str, pathlib.Path)):
        p = pathlib.Path(path)
        if not p.exists() and suffix and p.with_name(p.name + suffix).exists():
            p = p.with_name(p.name + suffix)
        if not p.is_file():
            raise FileNotFoundError(f"no checkpoint at {path}")
        return str(path), p.read_bytes()
    return "<stream>", path.read()


def open_zip(name: str, raw: bytes, what: str = "checkpoint") -> zipfile.ZipFile:
    """``raw`` as a zip archive whose every member was read and checked against its CRC."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(raw))
        bad = archive.testzip()
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError, NotImplementedError) as exc:
        raise CheckpointError(f"{name} is not a readable {what} (truncated or corrupt zip): {exc}") from exc
    if bad is not None:
        raise CheckpointError(f"{name} is not a readable {what} (truncated or corrupt zip): "
                              f"entry {bad!r} fails its checksum")
    infos = archive.infolist()
    if not infos or min(i.header_offset for i in infos) != 0:
        # the directory found is not the file's own: e.g. that of a zip stored inside a truncated one
        raise CheckpointError(f"{name} is not a readable {what} (truncated or corrupt zip): its directory "
                              "does not describe the file from its start")
    return archive


# ---------------------------------------------------------------------- tensors
def nonfinite_tensors(obj: Any, prefix: str = "") -> List[str]:
    """Dotted names of the floating-point tensors in ``obj`` (nested dicts, lists, tuples) that hold
    NaN or infinity."""
    out: List[str] = []
    if isinstance(obj, th.Tensor):
        if (obj.is_floating_point() or obj.is_complex()) and not bool(th.isfinite(obj).all()):
            out.append(prefix or "<tensor>")
    elif isinstance(obj, Mapping):
        for k, v in obj.items():
            out += nonfinite_tensors(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            out += nonfinite_tensors(v, f"{prefix}[{i}]")
    return out


def load_tensors(name: str, raw: bytes, entry: str) -> Any:
    """The tensors of ``entry`` of ``name`` read on the CPU with ``torch.load(weights_only=True)``;
    every floating-point tensor must be finite."""
    try:
        obj = th.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 (torch raises many kinds for a bad or unsafe file)
        raise CheckpointError(f"{name}: {entry} is not a readable weights-only tensor file "
                              f"({type(exc).__name__}: {exc})") from exc
    bad = nonfinite_tensors(obj)
    if bad:
        more = f" and {len(bad) - 3} more" if len(bad) > 3 else ""
        raise CheckpointError(f"{name}: {entry} holds non-finite values (NaN or infinity) in "
                              f"{', '.join(bad[:3])}{more}")
    return obj


# ---------------------------------------------------------------------- pickles read as data
_STRING_OPS = {"SHORT_BINUNICODE", "BINUNICODE", "BINUNICODE8", "UNICODE", "SHORT_BINSTRING", "BINSTRING", "STRING"}
_MEMO_PUT = {"PUT", "BINPUT", "LONG_BINPUT"}
_MEMO_GET = {"GET", "BINGET", "LONG_BINGET"}
_FRAMING = {"PROTO", "FRAME", "STOP"}
_INT_OPS = {"BININT", "BININT1", "BININT2", "INT", "LONG1"}


class _Global(tuple):
    """``(module, name)`` of a pickle's global reference."""


def _pickle_items(blob: bytes, extra_ops: FrozenSet[str] = frozenset()) -> Optional[List[Any]]:
    """The strings, integers and global references a pickle pushes, in order, read from its opcodes
    without running them; ``None`` when it uses an opcode outside the plain ones (and ``extra_ops``)."""
    items: List[Any] = []
    memo: Dict[int, Any] = {}
    last: Any = None
    try:
        for op, raw_arg, _ in pickletools.genops(blob):
            name = op.name
            arg: Any = raw_arg
            if name in _FRAMING:
                continue
            if name in _STRING_OPS:
                last = arg if isinstance(arg, str) else bytes(arg).decode("latin-1")
                items.append(last)
            elif name in _INT_OPS:
                last = int(arg)
                items.append(last)
            elif name == "MEMOIZE":
                memo[len(memo)] = last
            elif name in _MEMO_PUT:
                memo[int(arg)] = last
            elif name in _MEMO_GET:
                last = memo.get(int(arg))
                items.append(last)
            elif name == "STACK_GLOBAL":
                if len(items) < 2 or not all(isinstance(x, str) for x in items[-2:]):
                    return None
                module, qual = items.pop(-2), items.pop(-1)
                last = _Global((module, qual))
                items.append(last)
            elif name == "GLOBAL":
                module, _, qual = str(arg).partition(" ")
                last = _Global((module, qual))
                items.append(last)
            elif name in extra_ops:
                last = None
            else:
                return None
    except Exception:  # noqa: BLE001 (a malformed pickle is simply not one of the plain forms)
        return None
    return items


def _blob(entry: Mapping[str, Any]) -> bytes:
    try:
        return b64decode(str(entry[":serialized:"]).encode(), validate=True)
    except (Base64Error, ValueError) as exc:
        raise ValueError(f"its payload is not base64 ({exc})") from exc


def pickled_class_name(entry: Mapping[str, Any]) -> Optional[Tuple[str, str]]:
    """``(module, name)`` when the serialized ``entry`` is a bare reference to a class, else ``None``."""
    items = _pickle_items(_blob(entry))
    if items is None or len(items) != 1 or not isinstance(items[0], _Global):
        return None
    return items[0][0], items[0][1]


def imported_class(module: str, name: str) -> Optional[type]:
    """The class ``module.name`` if ``module`` is already imported (nothing is imported here)."""
    obj: Any = sys.modules.get(module)
    for part in name.split("."):
        obj = getattr(obj, part, None) if obj is not None else None
    return obj if isinstance(obj, type) else None


# ---------------------------------------------------------------------- rebuilders
@dataclass
class ReadContext:
    """What a rebuilder may use: the file's name, its whole ``data`` JSON, the environment the
    caller gave (if any), the archive's specification and the key being rebuilt."""

    name: str
    data: Dict[str, Any]
    env: Any
    spec: "ArchiveSpec"
    key: str = ""

    def fail(self, why: str) -> CheckpointError:
        return CheckpointError(f"{self.name}: entry {self.key!r} of its 'data': {why}")


Rebuilder = Callable[[Mapping[str, Any], ReadContext], Any]

_NUMPY_TYPE = re.compile(r"^<class 'numpy\.(\w+)'>$")
_SCALAR = r"-?(?:inf|nan|\d+(?:\.\d*)?(?:e[-+]?\d+)?)"
_BOX_REPR = re.compile(rf"'(\w+)': Box\(({_SCALAR}), ({_SCALAR}), \(([\d, ]*)\), (\w+)\)")


def _exact_token(token: str) -> bool:
    """Whether a number printed by numpy (8 significant digits at most) is its shortest exact form."""
    digits = re.sub(r"e.*$", "", token.lower()).lstrip("-").replace(".", "").lstrip("0")
    return token.lower().lstrip("-") in ("inf", "nan") or len(digits) < 8


def parse_array(text: Any, dtype: Any, shape: Sequence[int]) -> Optional[np.ndarray]:
    """The array numpy printed as ``text`` (``str(array)``), when the print is complete and exact."""
    if not isinstance(text, str) or "..." in text:
        return None
    tokens = text.replace("[", " ").replace("]", " ").split()
    size = int(np.prod(shape)) if len(shape) else 1
    if len(tokens) != size or not all(_exact_token(t) for t in tokens):
        return None
    try:
        arr = np.array([float(t) for t in tokens], dtype=np.float64).astype(np.dtype(dtype)).reshape(tuple(shape))
    except (ValueError, TypeError, OverflowError):
        return None
    return arr if str(arr) == text else None


def _box_from_entry(entry: Mapping[str, Any]) -> Any:
    from gymnasium import spaces

    try:
        dtype = np.dtype(str(entry["dtype"]))
        shape = tuple(int(s) for s in entry["_shape"])
    except (KeyError, TypeError, ValueError):
        return None
    low, high = parse_array(entry.get("low"), dtype, shape), parse_array(entry.get("high"), dtype, shape)
    if low is None or high is None:
        return None
    return spaces.Box(low=low, high=high, shape=shape, dtype=dtype)


def _dict_from_entry(entry: Mapping[str, Any]) -> Any:
    from gymnasium import spaces

    text = entry.get("spaces")
    if not isinstance(text, str):
        return None
    found = _BOX_REPR.findall(text)
    boxes: Dict[str, Any] = {}
    for key, low, high, shape, dtype in found:
        dims = tuple(int(s) for s in shape.replace(" ", "").split(",") if s)
        try:
            dt = np.dtype(dtype)
        except TypeError:
            return None
        box = spaces.Box(low=float(low), high=float(high), shape=dims, dtype=dt)
        boxes[key] = box
    space = spaces.Dict(boxes) if boxes else None
    return space if space is not None and str(space.spaces) == text else None


def _space_matches(space: Any, entry: Mapping[str, Any]) -> bool:
    """Whether ``space`` is the one the plain fields of ``entry`` describe."""
    from gymnasium import spaces

    kind = str(entry.get(":type:", ""))
    if isinstance(space, spaces.Dict):
        return "spaces.dict.Dict" in kind and str(space.spaces) == entry.get("spaces")
    if isinstance(space, spaces.Box):
        return ("spaces.box.Box" in kind and str(space.dtype) == entry.get("dtype")
                and list(space.shape) == list(entry.get("_shape") or []) and str(space.low) == entry.get("low")
                and str(space.high) == entry.get("high"))
    return False


def rebuild_space(entry: Mapping[str, Any], ctx: ReadContext) -> Any:
    """The space ``entry`` describes: from its plain fields when they give it exactly, else the given
    environment's or the recorded environment's space when that is the one described."""
    kind = str(entry.get(":type:", ""))
    parsed = (_dict_from_entry(entry) if "spaces.dict.Dict" in kind
              else _box_from_entry(entry) if "spaces.box.Box" in kind else None)
    if parsed is not None:
        return parsed
    candidates = []
    if ctx.env is not None:
        candidates.append(getattr(ctx.env, ctx.key, None))
    env_id = ctx.data.get("env_id")
    if isinstance(env_id, str) and env_id:
        try:
            import gymnasium as gym

            import safe_mapf_envs  # noqa: F401  (registers the ids)

            env = gym.make(env_id)
            candidates.append(getattr(env, ctx.key, None))
            env.close()
        except Exception:  # noqa: BLE001 (an id this installation does not know)
            pass
    for space in candidates:
        if space is not None and _space_matches(space, entry):
            return space
    raise ctx.fail(f"cannot rebuild the {kind or 'space'} it describes from its plain fields; pass env= "
                   "(an environment with that space)")


def class_rebuilder(base_path: Tuple[str, str]) -> Rebuilder:
    """A rebuilder for a class entry that must name an imported subclass of ``module.name``."""

    def rebuild(entry: Mapping[str, Any], ctx: ReadContext) -> Any:
        ref = pickled_class_name(entry)
        if ref is None:
            raise ctx.fail("not a plain reference to a class (refused: it would run code on loading)")
        base = imported_class(*base_path)
        cls = imported_class(*ref)
        if base is None or cls is None or not issubclass(cls, base):
            raise ctx.fail(f"it holds a {ref[1]!r} class ({ref[0]}), not a {base_path[1]}: it was not saved "
                           f"by {ctx.spec.owner}")
        return cls

    return rebuild


def _none(entry: Mapping[str, Any], ctx: ReadContext) -> Any:
    """Rollout state (last observations, episode starts): rebuilt empty, the next ``learn`` resets it."""
    return None


def _window(entry: Mapping[str, Any], ctx: ReadContext) -> Any:
    """An episode statistics window: rebuilt empty, of the model's window size."""
    if "collections.deque" not in str(entry.get(":type:", "")):
        raise ctx.fail(f"expected a deque, got {entry.get(':type:')!r}")
    size = ctx.data.get("_stats_window_size", 100)
    return collections.deque(maxlen=int(size) if isinstance(size, int) and size > 0 else 100)


_CONSTANT = re.compile(rf"^ConstantSchedule\(val=({_SCALAR})\)$")
_LINEAR = re.compile(rf"^LinearSchedule\(start=({_SCALAR}), end=({_SCALAR}), end_fraction=({_SCALAR})\)$")


def schedule_rebuilder(entry: Mapping[str, Any], ctx: ReadContext) -> Any:
    """A constant or linear schedule, from the plain fields Stable-Baselines3 stores with it."""
    from stable_baselines3.common.utils import ConstantSchedule, FloatSchedule, LinearSchedule

    kind = str(entry.get(":type:", ""))
    if kind.endswith(".ConstantSchedule'>") and isinstance(entry.get("val"), (int, float)):
        return ConstantSchedule(float(entry["val"]))
    if kind.endswith(".LinearSchedule'>") and all(isinstance(entry.get(k), (int, float))
                                                   for k in ("start", "end", "end_fraction")):
        return LinearSchedule(float(entry["start"]), float(entry["end"]), float(entry["end_fraction"]))
    if kind.endswith(".FloatSchedule'>"):
        inner = str(entry.get("value_schedule", ""))
        m = _CONSTANT.match(inner)
        if m:
            return FloatSchedule(float(m.group(1)))
        m = _LINEAR.match(inner)
        if m:
            return FloatSchedule(LinearSchedule(*(float(g) for g in m.groups())))
    raise ctx.fail(f"a schedule of type {kind!r} that cannot be rebuilt from its plain fields "
                   "(constant and linear schedules can); pass it as an override or in custom_objects")


def _train_freq(entry: Mapping[str, Any], ctx: ReadContext) -> Any:
    """``TrainFreq(frequency, unit)``, read from the pickle's integer and unit name (never run)."""
    from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit

    items = _pickle_items(_blob(entry), frozenset({"TUPLE1", "TUPLE2", "REDUCE", "NEWOBJ", "EMPTY_TUPLE"}))
    allowed = {("stable_baselines3.common.type_aliases", "TrainFreq"),
               ("stable_baselines3.common.type_aliases", "TrainFrequencyUnit")}
    if items is not None:
        globs = {tuple(x) for x in items if isinstance(x, _Global)}
        ints = [x for x in items if isinstance(x, int) and not isinstance(x, bool)]
        units = [x for x in items if isinstance(x, str) and x in ("step", "episode")]
        if globs <= allowed and len(ints) == 1 and len(units) == 1 and ints[0] >= 1:
            return TrainFreq(ints[0], TrainFrequencyUnit(units[0]))
    raise ctx.fail("not a plain TrainFreq(frequency, unit)")


def _action_noise(entry: Mapping[str, Any], ctx: ReadContext) -> Any:
    """Gaussian action noise, from the mean, scale and dtype stored in plain fields."""
    from stable_baselines3.common.noise import NormalActionNoise

    kind = str(entry.get(":type:", ""))
    m = _NUMPY_TYPE.match(str(entry.get("_dtype", "")))
    if kind.endswith(".NormalActionNoise'>") and m:
        mu, sigma = (entry.get(k) for k in ("_mu", "_sigma"))
        n = len(str(mu).replace("[", " ").replace("]", " ").split())
        mean, scale = parse_array(mu, np.float64, (n,)), parse_array(sigma, np.float64, (n,))
        if mean is not None and scale is not None:
            return NormalActionNoise(mean, scale, dtype=np.dtype(m.group(1)).type)
    raise ctx.fail(f"action noise of type {kind!r} that cannot be rebuilt from its plain fields "
                   "(Gaussian noise can); pass action_noise= as an override")


def _lagrangian(entry: Mapping[str, Any], ctx: ReadContext) -> Any:
    """The Lagrange multiplier, from its plain fields (limit, learning rate, cap, value, updates)."""
    from .lagrangian import LagrangeMultiplier

    if not str(entry.get(":type:", "")).endswith("agents.lagrangian.LagrangeMultiplier'>"):
        raise ctx.fail(f"expected a LagrangeMultiplier, got {entry.get(':type:')!r}")
    try:
        lm = LagrangeMultiplier(float(entry["cost_limit"]), float(entry["learning_rate"]), float(entry["value"]),
                                None if entry.get("max_value") is None else float(entry["max_value"]))
        lm.n_updates = int(entry.get("n_updates", 0))
    except (KeyError, TypeError, ValueError) as exc:
        raise ctx.fail(f"its plain fields do not describe a multiplier ({exc})") from exc
    if not all(math.isfinite(x) for x in (lm.cost_limit, lm.learning_rate, lm.value)):
        raise ctx.fail("the multiplier's fields are not finite")
    return lm


#: rebuilders of the serialized entries every Stable-Baselines3 algorithm stores
COMMON_REBUILDERS: Dict[str, Rebuilder] = {
    "observation_space": rebuild_space,
    "action_space": rebuild_space,
    "_last_obs": _none,
    "_last_original_obs": _none,
    "_last_episode_starts": _none,
    "ep_info_buffer": _window,
    "ep_success_buffer": _window,
    "lr_schedule": schedule_rebuilder,
    "learning_rate": schedule_rebuilder,
}

SB3_META_FILES = frozenset({"data", "_stable_baselines3_version", "system_info.txt", "pytorch_variables.pth"})


@dataclass
class ArchiveSpec:
    """What an algorithm's archive may hold.

    Attributes:
        owner: the algorithm's name (for messages).
        policy_base: ``(module, name)`` of the class every policy must subclass.
        params: the parameter files (without ``.pth``) the archive must hold.
        rebuilders: how each serialized entry is rebuilt; any other serialized entry is refused.
    """

    owner: str
    policy_base: Tuple[str, str]
    params: Tuple[str, ...]
    rebuilders: Dict[str, Rebuilder] = field(default_factory=dict)

    def rebuilder(self, key: str) -> Optional[Rebuilder]:
        if key == "policy_class":
            return class_rebuilder(self.policy_base)
        return self.rebuilders.get(key, COMMON_REBUILDERS.get(key))


@dataclass
class SafeArchive:
    """A Stable-Baselines3 archive read without unpickling: its bytes, its ``data`` with every
    serialized entry rebuilt, the rebuilt entries (``custom_objects`` for ``load``) and its tensors."""

    name: str
    raw: bytes
    data: Dict[str, Any]
    custom_objects: Dict[str, Any]
    params: Dict[str, Any]
    pytorch_variables: Optional[Dict[str, Any]]

    def stream(self) -> io.BytesIO:
        """The archive's bytes, for Stable-Baselines3's ``load`` (the very bytes checked here)."""
        return io.BytesIO(self.raw)


def read_sb3_archive(path: PathLike, spec: ArchiveSpec, custom_objects: Optional[Dict[str, Any]] = None,
                     env: Any = None, provided: Sequence[str] = ()) -> SafeArchive:
    """Read and check the whole Stable-Baselines3 archive at ``path`` without unpickling anything.

    Every member must pass its checksum; the members must be ``data``, the metadata files and
    exactly the parameter files of ``spec``; ``data`` must be a JSON object whose every
    ``":serialized:"`` entry ``spec`` knows how to rebuild (or ``custom_objects`` supplies, or
    ``provided`` names: values the caller sets after loading); every tensor is read weights-only
    and must be finite. Anything else raises :class:`CheckpointError` naming the file and the
    entry (``FileNotFoundError`` for a missing file).
    """
    name, raw = read_file_bytes(path)
    archive = open_zip(name, raw)
    names = archive.namelist()
    if "data" not in names:
        raise CheckpointError(f"{name} has no 'data' entry (not an SB3 checkpoint, or truncated or incomplete)")
    try:
        data = json.loads(archive.read("data").decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"{name}: its 'data' entry is not JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise CheckpointError(f"{name}: its 'data' entry is not a JSON object")
    missing = [k for k in ("policy_class", "observation_space", "action_space") if k not in data]
    if missing:
        raise CheckpointError(f"{name} is missing the keys {missing} in its 'data' entry")
    given = dict(custom_objects or {})
    ctx = ReadContext(name, data, env, spec)
    rebuilt: Dict[str, Any] = {}
    order = ["policy_class"] + [k for k in data if k != "policy_class"]
    for key in order:
        value = data[key]
        serialized = isinstance(value, dict) and ":serialized:" in value
        if key in ("policy_class", "observation_space", "action_space") and not serialized and key not in given:
            raise CheckpointError(f"{name}: entry {key!r} of its 'data' is not a serialized object "
                                  f"(got {type(value).__name__})")
        if not serialized:
            continue
        if key in given:
            rebuilt[key] = given[key]
            continue
        if key in provided:
            rebuilt[key] = None
            continue
        if not isinstance(value.get(":serialized:"), str):
            raise CheckpointError(f"{name}: entry {key!r} of its 'data' has a malformed payload")
        rebuild = spec.rebuilder(key)
        if rebuild is None:
            raise CheckpointError(f"{name}: entry {key!r} of its 'data' is a serialized "
                                  f"{value.get(':type:', 'object')} that {spec.owner} checkpoints do not hold "
                                  "(refused: it would run code on loading)")
        ctx.key = key
        try:
            rebuilt[key] = rebuild(value, ctx)
        except ValueError as exc:
            if isinstance(exc, CheckpointError):
                raise
            raise ctx.fail(str(exc)) from exc
    policy_class = rebuilt.get("policy_class", given.get("policy_class"))
    base = imported_class(*spec.policy_base)
    if not (isinstance(policy_class, type) and base is not None and issubclass(policy_class, base)):
        raise CheckpointError(f"{name} holds a {getattr(policy_class, '__name__', policy_class)!r} policy, "
                              f"not a {spec.policy_base[1]}: it was not saved by {spec.owner}")
    expected = {p + ".pth" for p in spec.params}
    absent = sorted(p for p in spec.params if p + ".pth" not in names)
    if absent:
        raise CheckpointError(f"{name} is missing the parameter files {[k + '.pth' for k in absent]}")
    foreign = sorted(set(names) - expected - SB3_META_FILES)
    if foreign:
        raise CheckpointError(f"{name} holds entries a {spec.owner} checkpoint does not: {foreign}")
    params = {p: load_tensors(name, archive.read(p + ".pth"), p + ".pth") for p in spec.params}
    for p, sd in params.items():
        if not isinstance(sd, dict):
            raise CheckpointError(f"{name}: {p}.pth is not a state dict")
    variables = None
    if "pytorch_variables.pth" in names:
        variables = load_tensors(name, archive.read("pytorch_variables.pth"), "pytorch_variables.pth")
        if variables is not None and not isinstance(variables, dict):
            raise CheckpointError(f"{name}: pytorch_variables.pth is not a dict of tensors")
    objects = {**rebuilt, **given}
    return SafeArchive(name, raw, {**data, **rebuilt}, objects, params, variables)


# ---------------------------------------------------------------------- the safe agent's archives
SAFE_GOAL_SPEC = ArchiveSpec(
    owner="SafeGoalTD3",
    policy_base=("agents.policies", "SafeGoalPolicy"),
    params=("policy", "actor.optimizer", "critic.optimizer", "cost_critic.optimizer"),
    rebuilders={
        "replay_buffer_class": class_rebuilder(("stable_baselines3.common.buffers", "ReplayBuffer")),
        "train_freq": _train_freq,
        "action_noise": _action_noise,
        "lagrangian": _lagrangian,
        "ep_cost_buffer": _window,
        "actor_learning_rate": schedule_rebuilder,
        "cost_learning_rate": schedule_rebuilder,
    },
)


def read_checkpoint(path: PathLike, custom_objects: Optional[Dict[str, Any]] = None, owner: str = "SafeGoalTD3",
                    env: Any = None, provided: Sequence[str] = ()) -> SafeArchive:
    """The checkpoint of a :class:`~agents.policies.SafeGoalPolicy` agent at ``path``, read and
    checked by :func:`read_sb3_archive` (``owner`` names the algorithm in the messages)."""
    from . import policies  # noqa: F401  (the policy class must be importable to be named)

    spec = SAFE_GOAL_SPEC if owner == SAFE_GOAL_SPEC.owner else ArchiveSpec(
        owner, SAFE_GOAL_SPEC.policy_base, SAFE_GOAL_SPEC.params, SAFE_GOAL_SPEC.rebuilders)
    return read_sb3_archive(path, spec, custom_objects=custom_objects, env=env, provided=provided)


def check_checkpoint(path: PathLike, custom_objects: Optional[Dict[str, Any]] = None,
                     owner: str = "SafeGoalTD3") -> str:
    """Check that ``path`` is a complete, safe checkpoint of a
    :class:`~agents.policies.SafeGoalPolicy` agent (see :func:`read_checkpoint`); a bad file raises
    :class:`CheckpointError` naming the problem (``FileNotFoundError`` for a missing file).
    Returns the name to use in later messages."""
    return read_checkpoint(path, custom_objects=custom_objects, owner=owner).name


__all__ = ["ArchiveSpec", "CheckpointError", "SAFE_GOAL_SPEC", "SafeArchive", "check_checkpoint", "class_rebuilder",
           "schedule_rebuilder",
           "load_tensors", "nonfinite_tensors", "open_zip", "read_checkpoint", "read_file_bytes",
           "read_sb3_archive", "rebuild_space"]
