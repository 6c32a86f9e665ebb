"""One parameter schema: each setting's default, help, range and choices live in its config dataclass field.

The node declares its ROS parameters from it, the CLIs build their flags from it, and params files are written
and checked against it. Names are dotted by section, as in KISS-ICP: ``recovery.search.n_scatter``,
``preprocess.max_range``. No dependency beyond the standard library (the core imports it).
"""
from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping, Optional


def param(default: Any, help: str, *, low: Optional[float] = None, high: Optional[float] = None,
          choices: Optional[tuple] = None, dynamic: bool = False, user: bool = False) -> Any:
    """A documented config field: ``low``/``high`` bound numbers, both inclusive (each number of a tuple),
    ``choices`` strings. :func:`validate` enforces them on construction, :meth:`Parameter.check` on overrides.
    ``dynamic``: the node reads it when it is used, so it may change at runtime (``ros2 param set``); the others
    are read once at start-up. ``user``: the tier a ROS user sets on a robot (topics, frames, range, device),
    shown first: the shipped params file holds these alone; the others are expert settings, declared and settable
    the same way."""
    return field(default=default, metadata={"help": help, "low": low, "high": high, "choices": choices,
                                            "dynamic": dynamic, "user": user})


def section(factory: Callable[[], Any], help: str) -> Any:
    """A nested config section (its fields are named ``<section>.<field>``)."""
    return field(default_factory=factory, metadata={"help": help})


@dataclass(frozen=True)
class Parameter:
    """One leaf of a config tree, as the node, the CLIs and the params file see it."""

    name: str  # dotted
    default: Any  # bool, int, float, str or a tuple of floats
    help: str
    low: Optional[float] = None
    high: Optional[float] = None
    choices: Optional[tuple] = None
    dynamic: bool = False  # settable at runtime (ros2 param set); else read once at start-up
    user: bool = False  # the user tier (the shipped params file, the docs' first table); else an expert setting

    @property
    def kind(self) -> type:
        return type(self.default)

    def describe(self) -> str:
        """The help with its range or choices, e.g. for a ROS parameter descriptor or a YAML comment."""
        limits = []
        if self.choices:
            limits.append("one of " + ", ".join(map(str, self.choices)))
        if self.low is not None or self.high is not None:
            limits.append(f"range [{'-inf' if self.low is None else self.low}, "
                          f"{'inf' if self.high is None else self.high}]")
        if self.dynamic:
            limits.append("settable at runtime")
        return self.help + (f" ({'; '.join(limits)})" if limits else "")

    def check(self, value: Any) -> Any:
        """``value`` converted to this parameter's type; ValueError naming the parameter if it does not fit."""
        kind = self.kind
        try:
            if kind is bool:
                if not isinstance(value, bool):
                    raise TypeError("expected true or false")
            elif kind is int:
                if isinstance(value, bool) or not float(value).is_integer():
                    raise TypeError("expected an integer")
                value = int(value)
            elif kind is float:
                if isinstance(value, bool):
                    raise TypeError("expected a number")
                value = float(value)
            elif kind is str:
                if not isinstance(value, str):
                    raise TypeError("expected a string")
            elif kind is tuple:
                value = tuple(float(v) for v in value)
                if len(value) != len(self.default):
                    raise TypeError(f"expected {len(self.default)} numbers")
        except (TypeError, ValueError) as err:
            raise ValueError(f"parameter {self.name}: {value!r}: {err}") from None
        _check_limits("parameter " + self.name, value, self.low, self.high, self.choices)
        return value


def _check_limits(name: str, value: Any, low: Optional[float], high: Optional[float],
                  choices: Optional[tuple]) -> None:
    """ValueError naming ``name`` if ``value`` (or any number of a tuple) is not a choice or not within [low, high]
    (NaN never is)."""
    if choices and value not in choices:
        raise ValueError(f"{name} must be one of {choices}, not {value!r}")
    numbers = value if isinstance(value, (tuple, list)) else (value,) if isinstance(value, (int, float)) else ()
    for v in numbers:
        if (low is not None and not low <= v) or (high is not None and not v <= high):
            raise ValueError(f"{name} = {value!r} outside [{low}, {high}]")


def validate(config: Any) -> None:
    """Check each :func:`param` field of a config dataclass against its metadata (call it in ``__post_init__``).

    Bounds are inclusive; a tuple keeps its default's length. Nested sections validate themselves; rules that
    relate several fields stay in the class's ``__post_init__``, after this call.
    """
    for f in dataclasses.fields(config):
        if "help" not in f.metadata or f.default is dataclasses.MISSING:  # a section (default_factory)
            continue
        name, value = f"{type(config).__name__}.{f.name}", getattr(config, f.name)
        if isinstance(f.default, tuple) and len(value) != len(f.default):
            raise ValueError(f"{name} must have {len(f.default)} values, not {len(value)}")
        _check_limits(name, value, f.metadata["low"], f.metadata["high"], f.metadata["choices"])


def parameters(config: Any, exclude: Iterable[str] = (), prefix: str = "") -> dict[str, Parameter]:
    """Every documented leaf of ``config`` (an instance: its values are the defaults), by dotted name."""
    excluded, out = set(exclude), {}
    for f in dataclasses.fields(config):
        name, value = prefix + f.name, getattr(config, f.name)
        if name in excluded:
            continue
        if "help" not in f.metadata:
            raise TypeError(f"{type(config).__name__}.{f.name} has no help: declare it with schema.param")
        if dataclasses.is_dataclass(value):
            out.update(parameters(value, excluded, name + "."))
        else:
            out[name] = Parameter(name, value, f.metadata["help"], f.metadata.get("low"), f.metadata.get("high"),
                                  f.metadata.get("choices"), f.metadata.get("dynamic", False),
                                  f.metadata.get("user", False))
    return out


def fields_of(config: Any, cls: type) -> dict[str, Any]:
    """The values of the fields ``cls`` declares, taken from ``config`` (a ``cls`` or a subclass): what builds a
    ``cls``, or a sibling subclass, from it."""
    return {f.name: getattr(config, f.name) for f in dataclasses.fields(cls)}


def values(config: Any, exclude: Iterable[str] = ()) -> dict[str, Any]:
    """The values in force, by dotted name (e.g. to log them at start-up)."""
    return {name: _get(config, name) for name in parameters(config, exclude)}


def build(config: Any, overrides: Mapping[str, Any], exclude: Iterable[str] = ()) -> Any:
    """A copy of ``config`` with dotted ``overrides`` checked and applied (each section validates itself)."""
    known = parameters(config, exclude)
    unknown = sorted(set(overrides) - set(known))
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; known: see docs/node.md or --help")
    tree: dict = {}
    for name, value in overrides.items():
        *path, leaf = name.split(".")
        node = tree
        for part in path:
            node = node.setdefault(part, {})
        node[leaf] = known[name].check(value)
    return _replace(config, tree)


def _replace(config: Any, tree: dict) -> Any:
    changes = {k: _replace(getattr(config, k), v) if isinstance(v, dict) else v for k, v in tree.items()}
    return dataclasses.replace(config, **changes)


def _get(config: Any, name: str) -> Any:
    for part in name.split("."):
        config = getattr(config, part)
    return config


def flatten_mapping(data: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested mappings (YAML sections) -> dotted names; dotted keys pass through."""
    out: dict[str, Any] = {}
    for key, value in data.items():
        name = prefix + str(key)
        if isinstance(value, Mapping):
            out.update(flatten_mapping(value, name + "."))
        else:
            out[name] = value
    return out


def params_yaml(params: Mapping[str, Parameter], header: str, node: str = "/**") -> str:
    """A ROS 2 params file of ``params`` at their defaults, each with its help as a comment."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines += [f"{node}:", "  ros__parameters:"]
    for p in params.values():
        lines.append(f"    # {p.describe()}")
        lines.append(f"    {p.name}: {_yaml_value(p.default)}")
    return "\n".join(lines) + "\n"


def _yaml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, tuple):
        return "[" + ", ".join(_yaml_value(float(v)) for v in value) + "]"
    return _yaml_float(value) if isinstance(value, float) else str(value)


def _yaml_float(value: float) -> str:
    """``value`` as YAML 1.1 reads a float: its exponent form needs a dot (``5e-07`` would be a string)."""
    text = repr(float(value))
    mantissa, e, exponent = text.partition("e")
    return text if not e or "." in mantissa else f"{mantissa}.0e{exponent}"


def add_arguments(parser: argparse.ArgumentParser, params: Mapping[str, Parameter], title: str) -> None:
    """One ``--<dotted.name>`` flag per parameter, also spelt with hyphens (absent flags keep the config's value)."""
    group = parser.add_argument_group(title)
    for p in params.values():
        default = list(p.default) if p.kind is tuple else p.default
        help_text = f"{p.describe()} (default: {default!r})".replace("%", "%%")  # argparse formats help strings
        kwargs: dict[str, Any] = {"dest": p.name, "default": argparse.SUPPRESS, "help": help_text}
        if p.choices:
            kwargs.update(type=p.kind, choices=p.choices)
        elif p.kind is bool:  # "--allow_pickle" alone means true
            kwargs.update(type=_boolean, nargs="?", const=True, metavar="{true,false}")
        elif p.kind is tuple:
            kwargs.update(type=float, nargs=len(p.default), metavar="X")
        else:
            kwargs.update(type=p.kind, metavar=p.kind.__name__.upper())
        flags = dict.fromkeys(["--" + p.name, "--" + p.name.replace("_", "-")])  # --allow_pickle, --allow-pickle
        group.add_argument(*flags, **kwargs)


def parsed_overrides(args: argparse.Namespace, params: Mapping[str, Parameter]) -> dict[str, Any]:
    """The flags of :func:`add_arguments` that were given, by dotted name."""
    return {name: value for name, value in vars(args).items() if name in params}


def _boolean(text: str) -> bool:
    lowered = text.strip().lower()
    if lowered not in ("true", "false", "1", "0", "yes", "no"):
        raise argparse.ArgumentTypeError(f"expected true or false, not {text!r}")
    return lowered in ("true", "1", "yes")
