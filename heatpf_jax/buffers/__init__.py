"""Measurement buffers: what is kept between heat maps and how it ages (III-C, eq. 2).
"""

from heatpf_jax.buffers.aging import (
    AgingBuffer,
    AgingParams,
    LatestOnly,
    NoParams,
)

__all__ = [
    "AgingBuffer",
    "AgingParams",
    "LatestOnly",
    "NoParams",
]
