"""Parameter properties: constraints, trainability, names, validation and unconstrained coordinates.

Every piece of the filter owns a ``NamedTuple`` of numbers (its params) and returns a tree of the
same structure whose leaves are :class:`Param` objects (its properties), the shape of dynamax's
``ParameterProperties``. One properties tree serves

* validation (:func:`validate`): one error that names the parameter and its allowed range;
* dtypes (:func:`as_arrays`): ``int32`` for integer parameters, ``float32`` otherwise;
* names (:func:`leaf_names`, :func:`set_by_name`): dotted paths (``motion.diffusion_std``) and the
  last component alone (``diffusion_std``) wherever it is unambiguous;
* tuning (:func:`to_unconstrained`, :func:`from_unconstrained`, :func:`partition`, :func:`combine`):
  ``log`` for a lower bound, ``logit`` for an interval; frozen parameters (discrete ones such as ``k``,
  and those whose effect is a count or a mask, e.g. ``threshold``) are left out of gradients.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "NoParams",
    "Param",
    "as_arrays",
    "combine",
    "from_unconstrained",
    "integer",
    "interval",
    "leaf_names",
    "make_params",
    "nonnegative",
    "partition",
    "positive",
    "resolve_name",
    "set_by_name",
    "to_unconstrained",
    "unit_interval",
    "validate",
]

_EPS = 1e-6  # how far inside a closed bound a boundary value lands in unconstrained coordinates


class NoParams(NamedTuple):
    """The params of a piece without numbers."""


@dataclass(frozen=True)
class Param:
    """What one parameter may be.

    Attributes:
        low, high: bounds (``-inf``/``inf`` for none).
        low_closed, high_closed: whether the bound itself is allowed.
        integer: an integer parameter (``int32``; always frozen).
        trainable: whether tuning by gradient may change it. Frozen parameters are discrete or act
            only through a count or a mask (their gradient is zero almost everywhere).
        allow_inf: ``high = inf`` itself is allowed (e.g. "no distance limit").
    """

    low: float = -math.inf
    high: float = math.inf
    low_closed: bool = True
    high_closed: bool = True
    integer: bool = False
    trainable: bool = True
    allow_inf: bool = False

    @property
    def dtype(self):
        return jnp.int32 if self.integer else jnp.float32

    def describe(self) -> str:
        if self.integer:
            return f"an integer in [{self.low:g}, {self.high:g}]"
        lo = "[" if self.low_closed else "("
        hi = "]" if self.high_closed and math.isfinite(self.high) else ")"
        return f"in {lo}{self.low:g}, {self.high:g}{hi}"

    def check(self, name: str, value: Any) -> None:
        """Raises ``ValueError`` starting with ``name:`` if a concrete value (or a batch element) is out of range."""
        if isinstance(value, jax.core.Tracer):
            return
        arr = np.asarray(value, dtype=np.float64)
        finite = np.isfinite(arr) | (self.allow_inf & (arr == np.inf))
        if not np.all(finite):
            raise ValueError(f"{name}: must be finite, got {value!r}")
        if self.integer and np.any(arr != np.round(arr)):
            raise ValueError(f"{name}: must be {self.describe()}, got {value!r}")
        ok_low = arr >= self.low if self.low_closed else arr > self.low
        ok_high = arr <= self.high if self.high_closed else arr < self.high
        if not (np.all(ok_low) and np.all(ok_high)):
            raise ValueError(f"{name}: must be {self.describe()}, got {value!r}")

    def to_unconstrained(self, x):
        """``log(x - low)`` above a bound, ``logit`` inside an interval; closed bounds are pulled in by 1e-6."""
        x = jnp.asarray(x, jnp.float32)
        lo_finite, hi_finite = math.isfinite(self.low), math.isfinite(self.high)
        if lo_finite and hi_finite:
            span = self.high - self.low
            p = jnp.clip((x - self.low) / span, _EPS, 1.0 - _EPS)
            return jnp.log(p) - jnp.log1p(-p)
        if lo_finite:
            return jnp.log(jnp.maximum(x - self.low, _EPS))
        if hi_finite:
            return jnp.log(jnp.maximum(self.high - x, _EPS))
        return x

    def from_unconstrained(self, u):
        u = jnp.asarray(u, jnp.float32)
        lo_finite, hi_finite = math.isfinite(self.low), math.isfinite(self.high)
        if lo_finite and hi_finite:
            return self.low + (self.high - self.low) * jax.nn.sigmoid(u)
        if lo_finite:
            return self.low + jnp.exp(u)
        if hi_finite:
            return self.high - jnp.exp(u)
        return u


def positive(*, trainable: bool = True, allow_inf: bool = False) -> Param:
    """``(0, inf)``."""
    return Param(low=0.0, low_closed=False, trainable=trainable, allow_inf=allow_inf)


def nonnegative(*, trainable: bool = True) -> Param:
    """``[0, inf)``."""
    return Param(low=0.0, trainable=trainable)


def unit_interval(*, low_closed: bool = True, high_closed: bool = True, trainable: bool = True) -> Param:
    """A share or probability in ``[0, 1]`` (ends open or closed)."""
    return Param(low=0.0, high=1.0, low_closed=low_closed, high_closed=high_closed, trainable=trainable)


def interval(low: float, high: float, *, trainable: bool = True) -> Param:
    """A closed interval ``[low, high]``."""
    return Param(low=low, high=high, trainable=trainable)


def integer(low: int, high: int) -> Param:
    """An integer in ``[low, high]``; discrete, so frozen (swept, never tuned)."""
    return Param(low=low, high=high, integer=True, trainable=False)


def _is_param(x) -> bool:
    return isinstance(x, Param)


def _key_name(key) -> str:
    for attr in ("name", "key", "idx"):
        if hasattr(key, attr):
            return str(getattr(key, attr))
    return str(key)


def leaf_names(properties) -> list[str]:
    """Dotted names of the leaves of a properties tree, in ``jax.tree.leaves`` order."""
    paths, _ = jax.tree_util.tree_flatten_with_path(properties, is_leaf=_is_param)
    return [".".join(_key_name(k) for k in path) for path, _ in paths]


def resolve_name(name: str, names: list[str]) -> str | None:
    """The full dotted name that ``name`` refers to: itself, or the one name whose last components match.

    Returns ``None`` when nothing matches.

    Raises:
        ValueError: ``name`` matches several parameters.
    """
    if name in names:
        return name
    matches = [n for n in names if n.endswith("." + name)]
    if len(matches) > 1:
        raise ValueError(f"{name}: ambiguous, give one of {', '.join(matches)}")
    return matches[0] if matches else None


def set_by_name(params, properties, updates: Mapping[str, Any], *, skip_unknown: bool = False):
    """``params`` with the leaves named in ``updates`` (dotted or unambiguous short names) replaced.

    Args:
        params: a params tree.
        properties: its properties tree.
        updates: ``{name: value}``.
        skip_unknown: leave names that match no parameter alone instead of raising (for settings
            shared by several models, each taking the names it has).

    Raises:
        ValueError: naming a parameter that is unknown (unless ``skip_unknown``) or ambiguous.
    """
    names = leaf_names(properties)
    leaves, treedef = jax.tree.flatten(params, is_leaf=lambda x: x is None)
    if len(leaves) != len(names):
        raise ValueError(f"params: expected {len(names)} parameters ({', '.join(names)}), got {len(leaves)}")
    for name, value in updates.items():
        full = resolve_name(name, names)
        if full is None:
            if skip_unknown:
                continue
            raise ValueError(f"{name}: unknown parameter (known: {', '.join(names)})")
        leaves[names.index(full)] = value
    return jax.tree.unflatten(treedef, leaves)


def make_params(model, updates: Mapping[str, Any] | None = None, **names: Any):
    """``model.default_params()`` with some leaves replaced by name (see :func:`set_by_name`)."""
    return set_by_name(model.default_params(), model.properties(), {**(updates or {}), **names})


def _pairs(params, properties) -> Iterable[tuple[str, Any, Param]]:
    names = leaf_names(properties)
    props = jax.tree.leaves(properties, is_leaf=_is_param)
    leaves = jax.tree.leaves(params, is_leaf=lambda x: x is None)
    if len(leaves) != len(props):
        raise TypeError(f"params: expected {len(props)} parameters ({', '.join(names)}), got {len(leaves)}")
    return zip(names, leaves, props, strict=True)


def validate(params, properties) -> None:
    """Raises ``ValueError`` naming the first concrete parameter out of range (batches: every element)."""
    for name, value, prop in _pairs(params, properties):
        prop.check(name, value)


def _as_array(prop: Param, value):
    if isinstance(value, jax.Array):  # traced or on a device: stay in JAX
        return value if value.dtype == prop.dtype else value.astype(prop.dtype)
    return np.asarray(value, np.int32 if prop.integer else np.float32)  # host values: no device work yet


def as_arrays(params, properties):
    """Every leaf as an array of its parameter's dtype (``int32`` or ``float32``).

    Host values (Python or NumPy numbers) become NumPy arrays, JAX arrays keep their device; either is
    a valid argument of a jitted step or run.
    """
    return jax.tree.map(_as_array, properties, params, is_leaf=_is_param)


def to_unconstrained(params, properties):
    """Trainable leaves mapped to unconstrained coordinates; frozen leaves unchanged."""
    return jax.tree.map(
        lambda p, v: p.to_unconstrained(v) if p.trainable else v, properties, params, is_leaf=_is_param
    )


def from_unconstrained(unconstrained, properties):
    """Inverse of :func:`to_unconstrained`."""
    return jax.tree.map(
        lambda p, v: p.from_unconstrained(v) if p.trainable else v, properties, unconstrained, is_leaf=_is_param
    )


def partition(params, properties):
    """``(trainable, frozen)``: two trees of the params' structure, ``None`` where a leaf belongs to the other.

    ``jax.grad`` takes the first (only float leaves); :func:`combine` joins them again.
    """
    trainable = jax.tree.map(lambda p, v: v if p.trainable else None, properties, params, is_leaf=_is_param)
    frozen = jax.tree.map(lambda p, v: None if p.trainable else v, properties, params, is_leaf=_is_param)
    return trainable, frozen


def combine(trainable, frozen):
    """Joins the two halves of :func:`partition`."""
    return jax.tree.map(lambda a, b: b if a is None else a, trainable, frozen, is_leaf=lambda x: x is None)
