"""The conventional measurement (section IV-B): one point per heat map from image-space clustering.

The paper compares against "a particle filter which takes the center of highest
activation from the same FCNN as a single relative measurement". Here: the
pixels at or above ``threshold`` are grouped into 8-connected components; the
component holding the strongest pixel is the detection; its activation-weighted
centroid in the image is projected onto the plane ``z = plane_height`` like any
heat-map pixel (Fig. 3). This is what throws information away: a split blob
(Fig. 7a) yields the centre of one half, a brighter false positive (Fig. 5)
wins outright.

Connected components are labelled in JAX by iterated minimum-label propagation
(each foreground pixel takes the smallest label among itself and its 8
neighbours until nothing changes), so the threshold stays a traced parameter.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from heatpf_jax.camera import ground_jacobian, project_pixel
from heatpf_jax.measurements import Measurements

__all__ = ["cluster_measurement", "connected_components", "strongest_cluster_centre"]


def _neighbour_min(labels: Int[Array, "h w"], background: int) -> Int[Array, "h w"]:
    padded = jnp.pad(labels, 1, constant_values=background)
    h, w = labels.shape
    out = labels
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            out = jnp.minimum(out, padded[di : di + h, dj : dj + w])
    return out


def connected_components(mask: Bool[ArrayLike, "h w"]) -> Int[Array, "h w"]:
    """Labels the 8-connected components of ``mask``.

    Returns:
        ``int32 [H, W]``: for each foreground pixel, the smallest raster index of
        its component; ``H * W`` for background pixels.
    """
    mask = jnp.asarray(mask, bool)
    h, w = mask.shape
    background = h * w
    init = jnp.where(mask, jnp.arange(h * w, dtype=jnp.int32).reshape(h, w), background)

    def body(state):
        labels, _ = state
        new = jnp.where(mask, _neighbour_min(labels, background), background)
        # Pointer jumping: follow each label to its own label, which shortens long chains.
        flat = new.ravel()
        jumped = jnp.where(mask.ravel(), jnp.concatenate([flat, jnp.array([background], jnp.int32)])[flat], background)
        jumped = jumped.reshape(h, w)
        return jumped, jnp.any(jumped != labels)

    labels, _ = lax.while_loop(lambda s: s[1], body, (init, jnp.array(True)))
    return labels


def strongest_cluster_centre(
    heatmap: Float[ArrayLike, "h w"], threshold: Float[ArrayLike, ""]
) -> tuple[Float[Array, "2"], Float[Array, ""], Bool[Array, ""]]:
    """Image-space centre of the component holding the strongest pixel at or above ``threshold``.

    Returns:
        ``(uv, peak, found)``: activation-weighted centroid ``(u, v)`` of that
        component, its peak activation, and whether any pixel passed.
    """
    heatmap = jnp.asarray(heatmap, jnp.float32)
    h, w = heatmap.shape
    mask = heatmap >= threshold
    labels = connected_components(mask)
    flat = jnp.where(mask, heatmap, -1.0).ravel()
    best = jnp.argmax(flat)
    found = flat[best] >= 0.0
    member = (labels.ravel() == labels.ravel()[best]) & mask.ravel()
    weights = jnp.where(member, heatmap.ravel(), 0.0)
    total = jnp.sum(weights)
    rows, cols = jnp.meshgrid(jnp.arange(h, dtype=jnp.float32), jnp.arange(w, dtype=jnp.float32), indexing="ij")
    safe_total = jnp.where(total > 0, total, 1.0)
    uv = jnp.stack([jnp.sum(weights * cols.ravel()), jnp.sum(weights * rows.ravel())]) / safe_total
    return uv, jnp.maximum(flat[best], 0.0), found & (total > 0)


def cluster_measurement(
    heatmap: Float[ArrayLike, "h w"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    *,
    threshold: Float[ArrayLike, ""],
    plane_height: Float[ArrayLike, ""],
    size: int = 1,
    max_distance: Float[ArrayLike, ""] = jnp.inf,
) -> Measurements:
    """The conventional single measurement, as a buffer of ``size`` slots (slot 0 used).

    Its weight is the cluster's peak activation, so aging (eq. 2) treats it like
    a heat-map pixel.
    """
    uv, peak, found = strongest_cluster_centre(heatmap, threshold)
    xy, ray_ok = project_pixel(uv, intrinsics, cam_to_base, plane_height, max_distance)
    valid = found & ray_ok
    first_valid = (jnp.arange(size) == 0) & valid
    footprint = ground_jacobian(uv, intrinsics, cam_to_base, plane_height)  # of the pixel at the centre
    return Measurements(
        xy=jnp.where(first_valid[:, None], jnp.broadcast_to(xy[None, :], (size, 2)), 0.0),
        weight=jnp.where(first_valid, peak, 0.0),
        valid=first_valid,
        footprint=jnp.where(first_valid[:, None, None], footprint[None], 0.0),
    )
