"""Differentiable tuning of a filter's continuous parameters with optax (``heatpf tune``).

Three parts:

* :func:`differentiable`: the same filter with gradient estimators in place, pieces wrapped, forward pass
  unchanged: stop-gradient resampling (:mod:`heatpf_jax.resampling.gradients`) and score-form motion
  gradients (:mod:`heatpf_jax.motion.score`) by default; every step under ``jax.checkpoint``
  (:class:`Checkpointed`), so the memory of a gradient through a ``lax.scan`` of T steps holds the
  carries, not every step's intermediates.
* losses: :func:`mse_loss` (squared error of the estimate after a burn-in) and :func:`nll_loss` (minus the
  mean per-step log-likelihood increment ``StepInfo.log_likelihood``).
* :func:`tune`: Adam (or any optax optimiser) on the trainable parameters in unconstrained coordinates
  (``log`` for positive, ``logit`` for unit-interval, :mod:`heatpf_jax.params`); each gradient step averages
  the loss over all training sequences and ``num_seeds`` filter seeds (vmapped; the same seeds for every
  sequence within a step, fresh seeds between steps), gradients clipped by their global norm.

Discrete parameters (``k``, sizes, the resampler) and those acting only through a count or a mask (the
heat-map ``threshold``, shares of explorers) are frozen (``Param.trainable``): their gradient is zero almost
everywhere. They are left to :func:`heatpf_jax.sweep.sweep`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from collections.abc import Sequence as Seq
from dataclasses import dataclass
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float, PRNGKeyArray

from heatpf_jax import params as P
from heatpf_jax.io.sequence import Sequence
from heatpf_jax.motion.score import ScoreMotion
from heatpf_jax.pieces import ModelWrapper
from heatpf_jax.resampling.gradients import DetachResampling, SoftResampling, StopGradientResampling
from heatpf_jax.rollout import prepare_run, run_core, validate_params

__all__ = [
    "LOSSES",
    "MOTION_GRADIENTS",
    "RESAMPLING_GRADIENTS",
    "Checkpointed",
    "TuneResult",
    "differentiable",
    "mse_loss",
    "nll_loss",
    "run_loss",
    "trainable_names",
    "tune",
]

RESAMPLING_GRADIENTS = ("stop_gradient", "soft", "detach", "none")
MOTION_GRADIENTS = ("score", "pathwise")


@dataclass(frozen=True)
class Checkpointed(ModelWrapper):
    """A model whose ``step`` is rematerialised in the backward pass (``jax.checkpoint``).

    ``run`` and the losses see the wrapped model's ``init``/``step`` unchanged in value; reverse-mode
    gradients through the ``lax.scan`` store one carry per step instead of every intermediate of it.

    Attributes:
        model: the wrapped model (a :class:`~heatpf_jax.filter.Filter` or any ``init``/``step`` model).
    """

    model: Any

    def step(self, key: PRNGKeyArray, state, inputs, params):
        return jax.checkpoint(self.model.step)(key, state, inputs, params)


def differentiable(
    model, *, resampling: str = "stop_gradient", motion: str = "score", checkpoint: bool = True
):
    """``model`` with gradient estimators in place of its resampling and motion pieces (values unchanged).

    Args:
        model: a :class:`~heatpf_jax.filter.Filter`.
        resampling: ``"stop_gradient"`` (default; Scibior and Wood), ``"soft"`` (Karkus et al.: changes the
            forward pass, its ``alpha`` is 0.5 unless set), ``"detach"`` (the control: gradients stop at
            resampling) or ``"none"`` (the filter's own strategy).
        motion: ``"score"`` (default; the transition density's score in the weights) or ``"pathwise"``
            (through the particle positions). A motion model without Gaussian noise
            (:class:`~heatpf_jax.motion.mass_inertia.MassInertia`) stays pathwise whatever is asked.
        checkpoint: wrap the step in ``jax.checkpoint`` (:class:`Checkpointed`).

    Raises:
        ValueError: naming the choice that is unknown.
    """
    if resampling not in RESAMPLING_GRADIENTS:
        raise ValueError(f"resampling: must be one of {list(RESAMPLING_GRADIENTS)}, got {resampling!r}")
    if motion not in MOTION_GRADIENTS:
        raise ValueError(f"motion: must be one of {list(MOTION_GRADIENTS)}, got {motion!r}")
    if not all(hasattr(model, piece) for piece in ("resampling", "motion", "_replace")):
        raise ValueError(f"model: {type(model).__name__} is not a particle filter (no resampling or motion pieces)")
    pieces = {}
    if resampling == "stop_gradient":
        pieces["resampling"] = StopGradientResampling(model.resampling)
    elif resampling == "detach":
        pieces["resampling"] = DetachResampling(model.resampling)
    elif resampling == "soft":
        resampler = getattr(model.resampling, "resampler", None)
        pieces["resampling"] = SoftResampling() if resampler is None else SoftResampling(resampler)
    if motion == "score" and hasattr(model.motion, "noise_std") and hasattr(model.motion, "transition"):
        pieces["motion"] = ScoreMotion(model.motion)
    out = model._replace(**pieces)
    return Checkpointed(out) if checkpoint else out


def mse_loss(info, truth: Float[Array, "t 2"], burn_in: int = 10) -> Float[Array, ""]:
    """Mean squared error (m^2) of ``info.mean`` against ``truth`` over the steps from ``burn_in`` on."""
    err = info.mean[burn_in:] - truth[burn_in:]
    return jnp.mean(jnp.sum(err * err, axis=-1))


def nll_loss(info, truth=None, burn_in: int = 0) -> Float[Array, ""]:
    """Minus the mean per-step log-likelihood increment (``StepInfo.log_likelihood``) from ``burn_in`` on.

    Summed over steps it is the negative log marginal likelihood of the heat maps; the mean keeps its
    scale independent of the length. Ground truth is not used.
    """
    del truth
    return -jnp.mean(info.log_likelihood[burn_in:])


LOSSES: dict[str, Callable] = {"mse": mse_loss, "nll": nll_loss}


def trainable_names(model) -> list[str]:
    """Dotted names of the parameters that gradients may change (``Param.trainable``)."""
    props = model.properties()
    flags = [p.trainable for p in jax.tree.leaves(props, is_leaf=lambda x: isinstance(x, P.Param))]
    return [n for n, f in zip(P.leaf_names(props), flags, strict=True) if f]


def _mask(model, names: Seq[str] | None):
    """Properties with ``trainable`` kept only for ``names`` (all trainable ones when ``None``)."""
    props = model.properties()
    all_names = P.leaf_names(props)
    allowed = trainable_names(model)
    if names is None:
        chosen = set(allowed)
    else:
        chosen = set()
        for name in names:
            full = P.resolve_name(name, all_names)
            if full is None:
                raise ValueError(f"tune: {name}: unknown parameter (trainable: {', '.join(allowed)})")
            if full not in allowed:
                raise ValueError(f"tune: {full}: not tunable by gradient (discrete, or acts through a count or a "
                                 "mask); sweep it instead")
            chosen.add(full)
        if not chosen:
            raise ValueError("tune: no parameter to tune")
    leaves, treedef = jax.tree.flatten(props, is_leaf=lambda x: isinstance(x, P.Param))
    leaves = [p if n in chosen else dataclasses.replace(p, trainable=False)
              for n, p in zip(all_names, leaves, strict=True)]
    return jax.tree.unflatten(treedef, leaves), sorted(chosen, key=all_names.index)


def _select(u, fixed, chosen, properties):
    """The trainable leaves: ``from_unconstrained(u)`` where ``chosen``, else their fixed (given) values."""
    return jax.tree.map(
        lambda prop, uu, fx, c: jnp.where(c, prop.from_unconstrained(uu), fx) if prop.trainable else None,
        properties, u, fixed, chosen, is_leaf=lambda x: isinstance(x, P.Param),
    )


def _batch_loss(u, fixed, chosen, frozen, keys, seqs, truths, model, loss, burn_in):
    """Mean loss over sequences (vmapped) and filter seeds (vmapped, the same for every sequence)."""
    props = model.properties()
    p = P.combine(_select(u, fixed, chosen, props), frozen)

    def one(seq, truth):
        return jnp.mean(jax.vmap(lambda k: run_loss(k, seq, truth, p, model, loss, burn_in))(keys))

    return jnp.mean(jax.vmap(one)(seqs, truths))


_STATIC = ("model", "loss", "burn_in")
_loss_jit = jax.jit(_batch_loss, static_argnames=_STATIC)
_loss_and_grad = jax.jit(jax.value_and_grad(_batch_loss), static_argnames=_STATIC)


def run_loss(key: PRNGKeyArray, sequence: Sequence, truth, params, model, loss: str = "mse", burn_in: int = 10):
    """The loss of one run (traced; ``sequence`` and ``params`` prepared by :func:`heatpf_jax.rollout.prepare_run`)."""
    info = run_core(key, sequence, params, model).info
    return LOSSES[loss](info, truth, burn_in)


class TuneResult(NamedTuple):
    """What :func:`tune` returns.

    Attributes:
        params: the tuned params (every parameter; the frozen ones as given).
        history: ``float [steps]`` the training loss of each gradient step (before its update).
        validation: ``float [V]`` the validation loss at ``validation_steps`` (empty without validation).
        validation_steps: ``int [V]`` the gradient steps (0: the start) at which it was measured.
        path: ``{name: float [steps + 1]}`` each tuned parameter's value before every step and at the end.
        names: the tuned parameters' dotted names.
        seconds: wall time of the whole tuning, compilation included.
    """

    params: Any
    history: np.ndarray
    validation: np.ndarray
    validation_steps: np.ndarray
    path: dict
    names: list
    seconds: float


def _stack(sequences: Seq[Sequence], params, model):
    if not sequences:
        raise ValueError("sequences: need at least one sequence")
    prepared, truths = [], []
    for i, seq in enumerate(sequences):
        if seq.ground_truth is None and truths is not None:
            truths = None
        elif truths is not None:
            truths.append(np.asarray(seq.ground_truth, np.float32))
        s, _ = prepare_run(seq, params, model)
        prepared.append(s)
        if s.heatmaps.shape != prepared[0].heatmaps.shape:
            raise ValueError(f"sequences: sequence {i} has heat maps of shape {s.heatmaps.shape}, sequence 0 "
                             f"{prepared[0].heatmaps.shape}; tune on sequences of one shape")
    stacked = jax.tree.map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *prepared)
    return stacked, (None if truths is None else np.stack(truths))


def tune(
    key: PRNGKeyArray,
    sequences: Seq[Sequence],
    init_params,
    model,
    *,
    names: Seq[str] | None = None,
    optimizer: optax.GradientTransformation | None = None,
    steps: int = 50,
    loss: str = "mse",
    num_seeds: int = 2,
    burn_in: int = 10,
    clip_norm: float = 1.0,
    validation: Seq[Sequence] | None = None,
    validate_every: int = 10,
    gradients: dict | None = None,
    callback: Callable[[int, float], None] | None = None,
) -> TuneResult:
    """Tunes ``names`` of ``init_params`` by gradient descent on ``loss`` over ``sequences``.

    Args:
        key: PRNG key (step i uses ``fold_in(key, i)``: fresh filter seeds every step, shared by the sequences).
        sequences: training sequences of one shape (with ``ground_truth`` for ``loss="mse"``).
        init_params: the starting point (:class:`~heatpf_jax.filter.FilterParams`), every parameter.
        model: the filter (the plain one: :func:`differentiable` is applied here).
        names: parameters to tune (dotted or short names); default every trainable one.
        optimizer: an optax optimiser on the unconstrained coordinates; default ``optax.adam(0.05)``.
        steps: gradient steps.
        loss: ``"mse"`` or ``"nll"`` (:data:`LOSSES`).
        num_seeds: filter seeds per sequence and step.
        burn_in: steps left out of the loss (convergence from the initial prior).
        clip_norm: ``optax.clip_by_global_norm`` bound on the gradient.
        validation: sequences whose loss is measured every ``validate_every`` steps (fixed seeds, so the
            curve shows the parameters' effect, not the seeds').
        validate_every: steps between validation losses.
        gradients: keyword arguments of :func:`differentiable` (default: stop-gradient resampling and
            score-form motion).
        callback: ``callback(step, loss)`` after every step (a progress bar).

    Returns:
        :class:`TuneResult`.

    Raises:
        ValueError: naming the argument or parameter that is unusable (before any compilation).
    """
    start = time.perf_counter()
    if loss not in LOSSES:
        raise ValueError(f"loss: must be one of {list(LOSSES)}, got {loss!r}")
    for name, value in (("steps", steps), ("num_seeds", num_seeds), ("validate_every", validate_every)):
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise ValueError(f"{name}: must be a positive integer, got {value!r}")
    if not isinstance(burn_in, int) or burn_in < 0:
        raise ValueError(f"burn_in: must be a non-negative integer, got {burn_in!r}")
    model.validate()
    validate_params(init_params, model)
    props, tuned = _mask(model, names)
    diff_model = differentiable(model, **(gradients or {}))
    train, truth = _stack(sequences, init_params, model)
    if loss == "mse" and truth is None:
        raise ValueError("sequences: loss 'mse' needs ground_truth in every training sequence")
    if burn_in >= train.heatmaps.shape[1]:
        raise ValueError(f"burn_in: {burn_in} leaves no step of the {train.heatmaps.shape[1]}-step sequences")
    val = val_truth = None
    if validation:
        val, val_truth = _stack(validation, init_params, model)
        if loss == "mse" and val_truth is None:
            raise ValueError("validation: loss 'mse' needs ground_truth in every validation sequence")
    optimizer = optimizer if optimizer is not None else optax.adam(0.05)
    optimizer = optax.chain(optax.clip_by_global_norm(clip_norm), optimizer)

    # One compilation per (model, loss, burn-in, shapes), shared by every tune() call whatever is tuned: the
    # gradient is taken for every trainable parameter, and ``chosen`` (a traced mask) keeps the others fixed.
    full = diff_model.properties()
    params = P.as_arrays(init_params, full)
    trainable, frozen = P.partition(params, full)
    chosen = jax.tree.map(lambda a: np.asarray(a.trainable), props, is_leaf=lambda x: isinstance(x, P.Param))
    chosen, _ = P.partition(chosen, full)
    u = P.to_unconstrained(trainable, full)
    with jax.numpy_dtype_promotion("standard"):
        opt_state = optimizer.init(u)

    @jax.jit
    def apply(grads, opt_state, u):
        # optax mixes Python floats and int32 counts, which strict dtype promotion refuses.
        with jax.numpy_dtype_promotion("standard"):
            updates, opt_state = optimizer.update(grads, opt_state, u)
            return optax.apply_updates(u, updates), opt_state

    def update(u, opt_state, keys, seqs, truths):
        value, grads = _loss_and_grad(u, trainable, chosen, frozen, keys, seqs, truths, diff_model, loss, burn_in)
        return (*apply(grads, opt_state, u), value)

    dummy = np.zeros((train.heatmaps.shape[0], 1, 2), np.float32)
    truths = dummy if truth is None else truth
    val_keys = jax.random.split(jax.random.fold_in(key, -1 & 0x7FFFFFFF), num_seeds)

    def constrained(u):
        return _select(u, trainable, chosen, full)

    def values(u):
        by_name = dict(zip(P.leaf_names(full), jax.tree.leaves(P.combine(constrained(u), frozen)), strict=True))
        return {n: float(by_name[n]) for n in tuned}

    path = {n: [] for n in tuned}
    history, val_hist, val_steps = [], [], []
    for i in range(steps + 1):
        for n, v in values(u).items():
            path[n].append(v)
        if val is not None and (i % validate_every == 0 or i == steps):
            vt = np.zeros((val.heatmaps.shape[0], 1, 2), np.float32) if val_truth is None else val_truth
            val_hist.append(float(_loss_jit(u, trainable, chosen, frozen, val_keys, val, vt, diff_model, loss,
                                            burn_in)))
            val_steps.append(i)
        if i == steps:
            break
        keys = jax.random.split(jax.random.fold_in(key, i), num_seeds)
        u, opt_state, value = update(u, opt_state, keys, train, truths)
        value = float(value)
        if not np.isfinite(value):
            raise FloatingPointError(f"tune: the loss became {value} at step {i}")
        history.append(value)
        if callback is not None:
            callback(i, value)
    out = P.combine(constrained(u), frozen)
    out = jax.tree.map(lambda x: np.asarray(x), out)
    return TuneResult(
        params=out,
        history=np.asarray(history),
        validation=np.asarray(val_hist),
        validation_steps=np.asarray(val_steps, np.int64),
        path={n: np.asarray(v) for n, v in path.items()},
        names=tuned,
        seconds=time.perf_counter() - start,
    )
