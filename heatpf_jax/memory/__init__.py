"""The long-term memory: tracks of every object seen, for hint particles (Olufs 3.4).

A small fixed-capacity track table fed by the particle filter.

The particle filter is the short-term memory: it loses an occluded ball within a few steps. The
long-term memory keeps *tracks* of what it sees, a hypothesis for every object, not only the ball (a
multiple-hypothesis tracker in the small): ``capacity`` slots, each a Kalman filter over ``(x, y, vx, vy)``
that rolls with friction. One step:

1. **predict** every track by ``dt``: constant velocity slowed by the rolling friction ``memory_friction``
   (m/s^2, the speed falls to 0 and stays; a ball rolls, it does not keep its speed), white-noise
   acceleration ``memory_accel_std`` (``memory_lost_accel_std`` while unobserved: an unseen ball rolls on), and
   the robot's motion (the ego-motion's ``tracks`` part, :mod:`heatpf_jax.motion.ego`);
2. **candidates**: the filter's modes (``Filter.modes``; the estimate when there are none) that are
   *observed*, i.e. have at least ``memory_min_support`` of buffered measurement weight within
   ``memory_support_radius``: a mode of particles with nothing under it is the filter guessing, not seeing.
   The memory observes the blob under the candidate, not the particles' mean, which passes between two blobs
   when the filter moves from one to the other: the centroid of the memory's own blob (step 4) holding the most of
   that weight (:func:`blob_under`; the centroid of the weight, :func:`observed_blob`, where it lies in no blob),
   so that a mode on its way from a vanishing ball to a distractor beside it is seen on one of them, never on a
   mean of the two that drags the ball's track over;
3. **associate** candidates to tracks within each track's **gate**: at most ``memory_gate`` metres *and*
   ``memory_redetect_sigmas`` Mahalanobis sigmas (``P_xy + memory_obs_std^2 I``) from its *prediction*, most
   likely pairs first (:func:`gate_costs`), and update those tracks (measurement std ``memory_obs_std``); their
   age returns to 0. A track is never moved by anything outside its gate. A *lost rolling* track's gate also
   holds only what its roll can have reached since it was last seen (:func:`motion_consistent`): nothing behind
   that place (a ball does not roll back) nor outside a cone of ``memory_lost_turn`` around its motion; a blob
   there opens a track of its own, or is left to the static track that explains it, while the lost track rolls on;
4. **re-detect**: the memory finds the blobs of the buffer itself (:func:`find_blobs`, up to ``max_blobs``: a
   pixel's footprint stretches a ball's pixels along the ray) and pairs them with its tracks, most likely pairs
   first, each blob's centroid inside the track's gate; a track no candidate took is re-detected at its blob when
   the blob weighs ``memory_min_support`` and ``memory_redetect_share`` of the track's usual blob (the paper: the
   memory "allows to re-detect vanished objects"). A blob another track explains better (a static distractor's)
   is not the ball's;
5. **birth**: an observed candidate outside every gate opens a track (in a free slot, else in the slot of
   the least useful track, never the ball's), and so does a blob of ``memory_birth_support`` outside every gate
   (at most ``max_births`` a step, only into free slots or the slots of memory-only tracks): a distractor that
   appears where no track predicts anything gets a track of its own at once;
6. **roles**: the **ball** (``TrackTable.ball``) is the track that carried the filter's estimate; it keeps
   the flag through an occlusion (the identity is kept by prediction, not by the nearest blob) and hands
   it over only when it is forgotten, or to a moving track carrying the estimate that the filter has found
   on more steps, or when the filter has not found it for ``memory_forget``. A confirmed track other than
   the ball whose speed stays below ``memory_static_speed`` is **static clutter** (``TrackTable.static``);
7. **forget**: a track unobserved for more than ``memory_forget`` seconds (2 s in the paper) is dropped.

Before the particles are weighted, :meth:`TrackMemory.recall` looks at this step's buffer for the tracks
the filter had lost (predicted to now, re-detected as in step 4): the paper's memory re-detects
vanished objects "using their new position as a new initial position for object tracking", and
:class:`~heatpf_jax.injection.memory_hints.RedetectionSeeds` seeds particles there in the same step, so the
frame on which the ball is seen again already weighs particles on it.

A track is *lost* by the filter when it is confirmed (observed on ``memory_confirm`` steps or more), no
candidate of the filter's was associated to it this step (re-detected or not), and it is the ball or a
track the filter carried that is not static clutter (:func:`lost_tracks`);
:class:`~heatpf_jax.injection.memory_hints.MemoryHints` then injects b hint particles around its position, the
ball's first, spread by the track's own covariance, which grows with its age (the paper: "an older age
will result in a larger spread") and shrinks again when the memory re-detects it.

Everything has fixed sizes (``capacity`` tracks, ``K`` candidates) and is jittable and vmappable.
:class:`NoMemory` is the default: a table of capacity 0.

The modules, by idea (none imports one listed after it):

* :mod:`~heatpf_jax.memory.params`: the memory's numbers, :class:`MemoryParams`;
* :mod:`~heatpf_jax.memory.table`: the track table (:class:`TrackTable`) and its queries (:func:`lost_tracks`);
* :mod:`~heatpf_jax.memory.predict`: step 1, the rolling prediction;
* :mod:`~heatpf_jax.memory.candidates`: step 2, the filter's candidates and the buffered weight under them;
* :mod:`~heatpf_jax.memory.gates`: the gates of step 3 (and a lost rolling track's cone) and the
  most-likely-first pairing;
* :mod:`~heatpf_jax.memory.blobs`: step 4, the memory's own blobs (:func:`find_blobs`) and re-detection;
* :mod:`~heatpf_jax.memory.update`: one whole step: associate, update, re-detect, birth, roles, forget;
* :mod:`~heatpf_jax.memory.track_memory`: the pieces, :class:`NoMemory` and :class:`TrackMemory`, and what
  :meth:`TrackMemory.recall` returns (:class:`Recall`).
"""

from heatpf_jax.memory.blobs import Blobs, find_blobs
from heatpf_jax.memory.candidates import blob_under, candidates_from, observed_blob, observed_support
from heatpf_jax.memory.gates import gate_costs, motion_consistent
from heatpf_jax.memory.params import MemoryParams
from heatpf_jax.memory.table import TrackTable, complete_tracks, empty_tracks, lost_tracks
from heatpf_jax.memory.track_memory import NoMemory, Recall, TrackMemory

__all__ = [
    "Blobs",
    "MemoryParams",
    "NoMemory",
    "Recall",
    "TrackMemory",
    "TrackTable",
    "blob_under",
    "candidates_from",
    "complete_tracks",
    "empty_tracks",
    "find_blobs",
    "gate_costs",
    "lost_tracks",
    "motion_consistent",
    "observed_blob",
    "observed_support",
]
