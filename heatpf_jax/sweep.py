"""Parameter sweeps: a batch of params through one sequence, in bounded memory, on every device.

``sweep`` runs :func:`heatpf_jax.run` for every parameter set of a batch (a
leading axis on every params leaf) of any model on the same sequence with the same
key (common random numbers, so differences between sets are not noise):

* the batch is sharded over the local devices with ``jax.shard_map`` on a
  one-axis ``Mesh`` (``"batch"``); on several hosts, call
  ``jax.distributed.initialize()`` first (on CPUs with
  ``jax_cpu_collectives_implementation="gloo"``) and pass ``devices=jax.devices()``:
  the same program then spans every host's devices, and every host receives the
  whole result (tested with two processes on one machine);
* on each device, ``lax.map(..., batch_size=chunk)`` vmaps ``chunk`` sets at a
  time, so peak memory grows with ``chunk``, not with the batch;
* the batch is padded (by repeating its last set) to a multiple of
  ``devices x chunk``, so one compilation serves any batch of that padded size;
* the sets run sorted by ``k`` when the model has one (results come back in the caller's order): the
  k-nearest search of a vmapped chunk runs as many selection rounds as the
  chunk's largest ``k``, so chunks of similar ``k`` waste the fewest.

:func:`sweep_memory` reports XLA's own memory analysis of the compiled sweep.
"""

from __future__ import annotations

from collections.abc import Sequence as PySequence
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P
from jaxtyping import PRNGKeyArray

from heatpf_jax import params as params_lib
from heatpf_jax.io.sequence import Sequence
from heatpf_jax.rollout import run, validate_params

__all__ = ["SweepMemory", "batch_size_of", "pad_params", "sweep", "sweep_memory"]


class SweepMemory(NamedTuple):
    """XLA's memory analysis of a compiled sweep, bytes (per device)."""

    argument_bytes: int
    output_bytes: int
    temp_bytes: int

    @property
    def peak_bytes(self) -> int:
        return self.argument_bytes + self.output_bytes + self.temp_bytes


def batch_size_of(params) -> int:
    """The leading batch size of stacked params."""
    sizes = {np.shape(v)[0] if np.ndim(v) else None for v in jax.tree.leaves(params)}
    if len(sizes) != 1 or None in sizes:
        raise ValueError(
            f"params_batch: every field needs the same leading batch axis, got sizes {sorted(map(str, sizes))}"
        )
    return int(sizes.pop())


def pad_params(params, size: int):
    """Pads a batch to ``size`` sets by repeating its last set."""
    n = batch_size_of(params)
    if size < n:
        raise ValueError(f"pad size {size} is smaller than the batch ({n})")
    idx = np.minimum(np.arange(size), n - 1)
    return jax.tree.map(lambda v: jnp.asarray(v)[idx], params)


def _mesh(devices: PySequence[jax.Device] | None) -> Mesh:
    devices = list(jax.local_devices() if devices is None else devices)
    return Mesh(np.array(devices), ("batch",))


def _k_leaf(model) -> int | None:
    """Index (in ``jax.tree.leaves`` order) of the model's parameter ``k``, if it has exactly one."""
    names = params_lib.leaf_names(model.properties())
    try:
        full = params_lib.resolve_name("k", names)
    except ValueError:
        return None
    return None if full is None else names.index(full)


@partial(jax.jit, static_argnames=("model", "chunk", "mesh"))
def _sweep_jit(key, sequence: Sequence, params, model, chunk: int, mesh: Mesh):
    def info_of(p):
        return run(key, sequence, p, model).info

    def local(p_local):
        # lax.map's batching cannot reshape size-0 leaves (no modes, the Kalman filter's ancestors):
        # map the others, and make those as zeros of their batched shape.
        count = jax.tree.leaves(p_local)[0].shape[0]
        shapes = jax.eval_shape(info_of, jax.tree.map(lambda x: x[0], p_local))
        specs, tree = jax.tree.flatten(shapes)
        empty = [spec.size == 0 for spec in specs]

        def nonempty(p):
            return [x for x, e in zip(jax.tree.leaves(info_of(p)), empty, strict=True) if not e]

        mapped = iter(lax.map(nonempty, p_local, batch_size=chunk))
        leaves = [jnp.zeros((count, *spec.shape), spec.dtype) if e else next(mapped)
                  for spec, e in zip(specs, empty, strict=True)]
        return jax.tree.unflatten(tree, leaves)

    # check_vma=False: the filter mixes per-set (varying) and shared values in lax.cond branches.
    return jax.shard_map(local, mesh=mesh, in_specs=P("batch"), out_specs=P("batch"), check_vma=False)(params)


def _prepare(key, sequence: Sequence, params_batch, model, chunk, devices):
    model.validate()
    validate_params(params_batch, model)
    n = batch_size_of(params_batch)
    mesh = _mesh(devices)
    n_dev = mesh.devices.size
    chunk = int(min(chunk or n, -(-n // n_dev)))
    if chunk < 1:
        raise ValueError(f"chunk: must be >= 1, got {chunk}")
    padded = -(-n // (n_dev * chunk)) * n_dev * chunk
    sharding = NamedSharding(mesh, P("batch"))
    # Sets sorted by k: a chunk's k-nearest loops run as many rounds as its largest k, so chunks of
    # similar k waste the fewest rounds. sweep() returns the results in the caller's order.
    arrays = params_lib.as_arrays(params_batch, model.properties())
    k_leaf = _k_leaf(model)
    order = np.arange(n) if k_leaf is None else np.argsort(np.asarray(jax.tree.leaves(arrays)[k_leaf]), kind="stable")
    host = jax.tree.map(np.asarray, pad_params(jax.tree.map(lambda v: v[order], arrays), padded))
    # Every process holds the whole (small) batch; each device takes its slice. This also builds the
    # global array when the mesh spans several hosts (after jax.distributed.initialize()).
    params = jax.tree.map(lambda v: jax.make_array_from_callback(v.shape, sharding, lambda i, v=v: v[i]), host)
    odometry = jnp.asarray(sequence.odometry, jnp.float32).at[0].set(0.0)
    sequence = sequence._replace(odometry=odometry, ground_truth=None, stamps=None, settings=None)
    return key, sequence, params, model, chunk, mesh, (n, order)


def sweep(
    key: PRNGKeyArray,
    sequence: Sequence,
    params_batch,
    model,
    *,
    chunk: int | None = None,
    devices: PySequence[jax.Device] | None = None,
):
    """Runs ``model`` once per parameter set of ``params_batch`` on ``sequence``.

    Args:
        key: PRNG key, shared by every parameter set (common random numbers).
        sequence: one sequence.
        params_batch: the model's params with a leading batch axis B on every leaf
            (see :func:`heatpf_jax.stack_params`).
        model: the model (a :class:`~heatpf_jax.Filter` or a baseline), shared by the batch.
        chunk: parameter sets vmapped together on a device (default: all of the
            device's share); peak memory grows with it.
        devices: devices to shard the batch over (default: ``jax.local_devices()``).

    Returns:
        The model's step info with leading axes ``[B, T]``; equal to
        ``jax.vmap(lambda p: run(key, sequence, p, model).info)(params_batch)`` up to float32
        rounding. Batched and single programs round differently in their last bits, and
        resampling can amplify that over hundreds of steps into differences of the size of the
        filter's own Monte Carlo spread (a few cm on the standard scenario at 300 steps).
    """
    key, sequence, params, model, chunk, mesh, (n, order) = _prepare(
        key, sequence, params_batch, model, chunk, devices
    )
    info = _sweep_jit(key, sequence, params, model, chunk, mesh)
    if not all(leaf.is_fully_addressable for leaf in jax.tree.leaves(info)):  # several hosts: gather
        from jax.experimental import multihost_utils

        info = multihost_utils.process_allgather(info, tiled=True)
    back = np.argsort(order)  # from the k-sorted order back to the caller's
    return jax.tree.map(lambda v: v[:n][back], info)


def sweep_memory(
    key: PRNGKeyArray,
    sequence: Sequence,
    params_batch,
    model,
    *,
    chunk: int | None = None,
    devices: PySequence[jax.Device] | None = None,
) -> SweepMemory:
    """XLA's memory analysis (arguments, outputs, temporaries; per device) of the compiled sweep."""
    args = _prepare(key, sequence, params_batch, model, chunk, devices)[:-1]
    stats = _sweep_jit.lower(*args).compile().memory_analysis()
    return SweepMemory(
        argument_bytes=int(stats.argument_size_in_bytes),
        output_bytes=int(stats.output_size_in_bytes),
        temp_bytes=int(stats.temp_size_in_bytes),
    )
