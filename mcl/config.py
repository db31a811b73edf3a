"""Configuration: frozen dataclasses and a validating YAML loader.

``load_config(path, overrides)`` reads a YAML file (or nothing, for the
defaults), applies ``--set section.key=value`` overrides through the same
validator, and returns a :class:`Config`. Unknown keys are errors with the
dotted path and a did-you-mean; wrong types and out-of-range values are errors
naming the key; nothing is silently replaced by a default.

Paths in a config file (``map``, ``log``, ``truth``, ``landmarks.map``, ``planes.depth``, ``planes.map``)
are resolved relative to the config file's folder first and, if nothing exists there, to the current
directory; the resolved config stores absolute paths so a run can be repeated
from anywhere.
"""

from __future__ import annotations

import copy
import dataclasses
import importlib.resources
import difflib
import math
import re
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml

from mcl.errors import ConfigError
from mcl.yamlfile import finite_number, load_text, read_yaml, short_repr

PROJECT_ROOT = Path(__file__).resolve().parents[1]


def shipped(rel: str) -> Path:
    """A file the project ships (``configs/default.yaml``, ``configs/baseline.yaml``, ``data/demo/...``): the
    repository's copy in a source tree or an editable install, else the installed package's (``mcl/_project/``,
    copied there when the wheel is built, see setup.py), read through importlib.resources."""
    repo = PROJECT_ROOT / rel
    if repo.exists():
        return repo
    return Path(str(importlib.resources.files("mcl").joinpath("_project", *rel.split("/"))))


# Ranges a number may take: (min, max, min_inclusive, max_inclusive). Checked by
# `_check_range` for every field whose metadata names one.
def _rng(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False, hi_open: bool = False):
    return {"range": (lo, hi, lo_open, hi_open)}


@dataclass(frozen=True, slots=True, kw_only=True)
class FilterConfig:
    """The particle filter loop (Prob. Rob. Table 8.2, MCL)."""

    particles: int = field(default=5000, metadata=_rng(1, 10_000_000))
    initial_pose: tuple[float, float, float] | None = None  # x, y, theta; null -> global
    initial_std: tuple[float, float, float] = (0.1, 0.1, 0.1)  # std of x, y (m) and theta (rad)
    global_localization: bool = False  # uniform over free space, ignoring initial_pose
    resampling: Literal["systematic", "stratified", "residual", "multinomial"] = "systematic"
    resample_threshold: float = field(default=0.5, metadata=_rng(0.0, 1.0))  # resample when ESS/N < this
    ess_floor: float = field(default=0.0, metadata=_rng(0.0, 1.0))  # temper a tracking scan so ESS/N stays above this
    ess_floor_spread: float = field(default=0.08, metadata=_rng(0.0, None))  # ... only a cloud this wide (m or rad)
    update_min_d: float = field(default=0.05, metadata=_rng(0.0))  # m travelled before an update (AMCL)
    update_min_a: float = field(default=0.05, metadata=_rng(0.0))  # rad turned before an update (AMCL)
    # estimate: mean of the heaviest cluster (AMCL's pf_cluster_stats) or of the whole set (mcl.clusters)
    estimate: Literal["cluster", "mean"] = "cluster"
    # m, histogram cell for clusters (a cell key overflows below a mm)
    cluster_size: float = field(default=0.5, metadata=_rng(1e-3))
    cluster_angle: float = field(default=0.5236, metadata=_rng(0.0, 6.2832, lo_open=True))  # rad, its theta cell
    # degenerate input (mcl.filter): an odometry step longer than this is a jump, not motion
    max_odom_step: float = field(default=2.0, metadata=_rng(0.0, lo_open=True))  # m
    # ... and longer than this many times the longest of the last 20 steps taken (0: the fixed bound alone)
    max_odom_ratio: float = field(default=3.0, metadata=_rng(0.0))
    # ... unless its speed over the time since the last scan is at most this (m/s), or max_odom_ratio times the
    # fastest of the last 20 steps' (a laser silent for seconds: the next scan comes metres on at the robot's speed;
    # 0: off)
    max_odom_speed: float = field(default=2.0, metadata=_rng(0.0))
    respread_std: tuple[float, float, float] = (0.5, 0.5, 0.5)  # std x, y (m), theta (rad) of a re-spread
    # KLD sampling (Fox 2003, Prob. Rob. Table 8.4; mcl.adaptive): with kld on, `particles` is the
    # maximum (and the count drawn at initialisation, as AMCL's max_particles) and each resample draws
    # between min(min_particles, particles) and particles, as many as the occupied histogram bins call
    # for (so `--particles 100` on a config with min_particles 250 runs a fixed 100).
    kld: bool = False
    min_particles: int = field(default=500, metadata=_rng(1, 10_000_000))
    kld_epsilon: float = field(default=0.05, metadata=_rng(0.0, 1.0, lo_open=True))  # bound on the KL error
    kld_delta: float = field(default=0.01, metadata=_rng(0.0, 1.0, lo_open=True, hi_open=True))  # P(error > eps)
    kld_bin_xy: float = field(default=0.5, metadata=_rng(0.0, lo_open=True))  # histogram bin side (m)
    kld_bin_theta: float = field(default=0.1745, metadata=_rng(0.0, 6.2832, lo_open=True))  # bin width (rad)
    # Recovery (mcl.adaptive): poses drawn from free space instead of the weighted set at resampling.
    # lost: recovery_fraction of N while the quality signal says the filter is lost (mcl.quality);
    # augmented: the book's augmented MCL (Table 8.3), p = max(0, 1 - w_fast/w_slow); true is augmented;
    # auto: augmented for global localization, off when tracking from a pose; false: never.
    recovery: bool | Literal["lost", "augmented", "auto"] = False
    recovery_fraction: float = field(default=0.1, metadata=_rng(0.0, 1.0, lo_open=True))
    # lost: std x, y (m), theta (rad) around the estimate
    recovery_local_std: tuple[float, float, float] = (0.5, 0.5, 0.3)
    # lost: lost updates before the spread around the estimate (and the tempered scan) while the lost scans look
    # occluded; a scan that refutes the estimate (mcl.quality.ScanQuality.refutes) spreads at once. 0: always at once
    recovery_wait: int = field(default=0, metadata=_rng(0, 10_000))
    # lost: the pose reported at the next update is the whole set's estimate or the older particles' alone,
    # whichever fits the scan better (ParticleFilter._trial_estimate)
    recovery_trial: bool = False
    # lost: the spread around the estimate runs protected, as a re-seed does (reseed_odds > 0): the spread poses and
    # the track resampled apart, the estimate kept on the track until the spread poses out-score it (ProtectedReseed)
    recovery_protect: bool = False
    recovery_global_after: int = field(default=10, metadata=_rng(0, 1_000_000))  # lost updates before uniform draws
    # ... or this many seconds of log time lost (after at least quality.lost_after lost updates), whichever comes
    # first: a log with a scan every 3 s (intel_lab) is otherwise lost for 30 s before the re-seed. 0: updates only
    recovery_global_after_s: float = field(default=0.0, metadata=_rng(0.0, 1e9))
    # ... but recovery_global_after updates count only once they span this many seconds of log time: at 10-40 Hz
    # ten updates are 0.25-1 s, shorter than the ground hits or the crowd that made a correct track look lost (the
    # number of updates was chosen at 5 Hz, where ten span 1.8 s). 0: updates alone
    recovery_global_min_s: float = field(default=0.0, metadata=_rng(0.0, 1e9))
    # lost: a lost call within this many seconds of log time after a lost episode that ended without a re-seed (the
    # track, or a spread pose near it, fitting again) re-seeds at once (mcl.adaptive.LostRecovery.relapsed; 0: off)
    recovery_relapse_s: float = field(default=0.0, metadata=_rng(0.0, 1e9))
    recovery_reseed: bool = True  # lost: after global_after lost updates add a whole global set (not 5 % a step)
    # updates after a search a lost call re-seeds
    recovery_probation: int = field(default=0, metadata=_rng(0, 1_000_000))
    # the probation after a global search counts from its first update whose estimate fits the scan (fit: holding
    # ends), or starts again when its heaviest cluster settles after that (settled: tempering ends)
    recovery_probation_from: Literal["fit", "settled"] = "fit"
    # ... and lasts at least this many seconds of log time: at 10-40 Hz fifty updates are 1.3-5 s (the number was
    # chosen at 5 Hz, where it spans 10 s). 0: updates alone
    recovery_probation_min_s: float = field(default=0.0, metadata=_rng(0.0, 1e9))
    # lost: after a global search, re-seed when over stall_window s of log time the odometry moved >= stall_travel m
    # and the estimate less than stall_ratio times as far (mcl.adaptive.StallCheck; 0: off); for stall_active s
    stall_ratio: float = field(default=0.0, metadata=_rng(0.0, 1.0))
    stall_window: float = field(default=3.0, metadata=_rng(0.0, 1e6, lo_open=True))
    stall_travel: float = field(default=1.5, metadata=_rng(0.0, 1e6, lo_open=True))
    stall_active: float = field(default=60.0, metadata=_rng(0.0, 1e9))
    # prior mass of the old cloud
    recovery_reseed_keep: float = field(default=0.5, metadata=_rng(0.0, 1.0, lo_open=True))
    # an unprotected re-seed that kept the old cloud: until the filter is no longer lost, the pose reported is the
    # old estimate moved by the odometry, not the heaviest cluster of the uniform poses (ParticleFilter._report_held;
    # the pose reported only)
    reseed_hold_pose: bool = True
    reseed_odds: float = field(default=0.0, metadata=_rng(0.0, 1e6))  # nats of log-odds that settle a protected re-seed
    # a global re-seed due while lost recovery's protected spread leads, unsettled, waits while the track's last scan
    # scores at least this (ProtectedReseed.defers_reseed); 0: off, the re-seed keeps the leading side at once
    reseed_wait_fit: float = field(default=0.0, metadata=_rng(0.0, 1.0))
    # a place a search found is challenged once (a protected re-seed) when the median quality score of
    # ProbationChallenge.WINDOW updates in a row on probation is below this; 0: off
    probation_fit: float = field(default=0.0, metadata=_rng(0.0, 1.0))
    global_density: float = field(default=0.0, metadata=_rng(0.0, 1e6))  # uniform candidates per m2 of free space
    # laser log-lik x this while searching
    search_exponent: float = field(default=1.0, metadata=_rng(0.0, 1.0, lo_open=True))
    lost_exponent: float = field(default=1.0, metadata=_rng(0.0, 1.0, lo_open=True))  # ... while lost (lost recovery)
    # while searching, every particle first takes this many scan-matching steps (ParticleFilter._match_scan); 0: off
    search_refine: int = field(default=0, metadata=_rng(0, 50))
    search_refine_dist: float = field(default=0.5, metadata=_rng(0.0, 1e3, lo_open=True))  # endpoints farther: left out
    # which particles: every one at every update while the search tempers, or only a search's fresh uniform poses,
    # once, at their first scan
    search_refine_scope: Literal["tempering", "fresh"] = "tempering"
    # the best of the uniform candidates global_density scores per fresh pose is matched (search_refine steps) and
    # the fresh poses drawn by their matched fit; the evidence stays the mean likelihood of all of them as drawn
    search_refine_candidates: bool = False
    # a global search settles only once its heaviest cluster's x and y std are under this (m) too; 0: by weight alone
    search_settled_std: float = field(default=0.0, metadata=_rng(0.0, 1e6))
    recovery_alpha_slow: float = field(default=0.001, metadata=_rng(0.0, 1.0, lo_open=True))
    recovery_alpha_fast: float = field(default=0.1, metadata=_rng(0.0, 1.0, lo_open=True))


@dataclass(frozen=True, slots=True, kw_only=True)
class MotionConfig:
    """Odometry motion model (Prob. Rob. Table 5.6, sample_motion_model_odometry; with ``noise_step`` 0.3 m by
    default, a step over 0.3 m has the translation-driven noise of a random walk of 0.3 m steps: ``noise_step=0``
    is the book's table exactly)."""

    # odometry: sample_motion_model_odometry (Table 5.6); velocity: sample_motion_model_velocity (Table 5.3);
    # omni: the odometry of an omnidirectional base (ROS AMCL's omni model, mcl.motion.OmniMotionModel)
    model: Literal["odometry", "velocity", "omni"] = "odometry"
    # variance: sigma^2 = alpha1*drot1^2 + alpha2*dtrans^2 (the book's Table 5.6 and AMCL);
    # std: sigma = alpha1*|drot1| + alpha2*|dtrans| (the lecture slides' form).
    noise_form: Literal["variance", "std"] = "variance"
    alpha1: float = field(default=0.05, metadata=_rng(0.0))  # rotation noise from rotation
    alpha2: float = field(default=0.05, metadata=_rng(0.0))  # rotation noise from translation
    alpha3: float = field(default=0.05, metadata=_rng(0.0))  # translation noise from translation
    alpha4: float = field(default=0.05, metadata=_rng(0.0))  # translation noise from rotation
    # velocity model only (Table 5.3): the final rotation gamma; variance form sigma_g^2 = alpha5 v^2 + alpha6 w^2
    alpha5: float = field(default=0.01, metadata=_rng(0.0))  # final-rotation noise from translational velocity
    alpha6: float = field(default=0.01, metadata=_rng(0.0))  # final-rotation noise from rotational velocity
    # omni model only: the noise across the direction of travel from translation (AMCL's omni alpha5); variance
    # form sigma_strafe^2 = alpha_strafe trans^2 + alpha4 rot^2
    alpha_strafe: float = field(default=0.05, metadata=_rng(0.0))
    # m: a step longer than this has the translation-driven noise (alpha2, alpha3, alpha_strafe) of a random walk of
    # such steps, dtrans^2 -> dtrans * min(dtrans, noise_step) (mcl.motion.noise_trans); 0: the book's dtrans^2
    noise_step: float = field(default=0.3, metadata=_rng(0.0))
    # with model odometry: "omni" runs an odometry whose travel goes across the robot's heading (an omnidirectional
    # base: mcl.motion.sideways_share >= SIDEWAYS_OMNI) with the omni model, with a warning; "keep" warns only
    sideways: Literal["omni", "keep"] = "omni"
    # odometry that holds one pose while the scans show the robot moving (a hung encoder driver): "fill" takes the
    # motion there from scan matching (mcl.odomstall), with a warning; "keep" leaves it still (every scan gated)
    stalls: Literal["fill", "keep"] = "keep"
    # an odometry step the filter would call a jump (filter.max_odom_step, max_odom_ratio, max_odom_speed: a base
    # driver that restarted from 0 0 0, a glitch) and faster than 5 m/s or with the scans not overlapping at it:
    # "match" takes that step from scan matching and moves the odometry
    # after it to go on from there (mcl.odomstall), with a warning; "hedge" leaves it to the filter (half the
    # particles take the step, the others are re-spread where they were)
    jumps: Literal["match", "hedge"] = "hedge"
    # a step of the odometry that turns 0.15 rad or more while the scans turn 0.15 rad and half their own turn less
    # (a wheel that slips: it reads travel the robot did not make, and turns it): "match" takes that step from scan
    # matching and moves the odometry after it to go on from there (mcl.odomstall), with a warning; "keep" leaves it
    slips: Literal["match", "keep"] = "keep"
    # a step whose odometry the stall fill took from scan matching (motion.stalls: fill) has its travel known only
    # so well: its translation std gets fill_spread times the travel more (in quadrature). Scans seconds apart, or
    # along a corridor, do not pin the motion, and the match then takes its guess (the velocity before the hold).
    # 0: the filled step is trusted like the odometry's own
    fill_spread: float = field(default=0.0, metadata=_rng(0.0))
    # the noise's distribution (mcl.noise), all with the std above: normal (NumPy's exact normal),
    # normal_twelve (sum of twelve uniforms) or triangular (two uniforms)
    noise: Literal["normal", "normal_twelve", "triangular"] = "normal"
    map_rejection: bool = True  # map-based motion model (seed 5.5): resample poses that land off free space
    # a pose on an unknown cell (a map's unexplored floor, a closed door's room, the floor under furniture moved
    # since): "fallback" draws again as off free space, but a particle whose every try lands off free space keeps its
    # last try when that is on an unknown cell (a robot on a grey patch keeps its particles); "reject" gives it
    # weight zero (mcl before the thirty-third session: every particle died while the robot drove over a grey patch);
    # "free" takes unknown for free (then a cloud leaks off the known floor through a map's gaps)
    map_unknown: Literal["fallback", "reject", "free"] = "fallback"
    max_tries: int = field(default=10, metadata=_rng(1, 1000))
    robot_radius: float = field(default=0.0, metadata=_rng(0.0))  # m of clearance a pose needs
    # Odometry faults (wheel slip, a bump, a bad encoder; an mcl extension): while the filter is lost, and for
    # fault_window updates after, on a track that had held for as long, the motion model is the mixture
    # (1 - fault_prob) p(x'|u,x) + fault_prob p_k(x'|u,x), p_k the same model with every sigma times fault_scale.
    # fault_share of the particles are drawn from p_k and importance-weighted back to the mixture. 0: never.
    fault_prob: float = field(default=0.0, metadata=_rng(0.0, 1.0, hi_open=True))
    fault_scale: float = field(default=10.0, metadata=_rng(1.0))
    fault_share: float = field(default=0.05, metadata=_rng(0.0, 1.0, lo_open=True, hi_open=True))
    fault_window: int = field(default=50, metadata=_rng(0, 1_000_000))  # updates after a lost call
    # ... and at most this many seconds of log time after the window's last lost update (0: no bound): a sparse log's
    # 50 updates are 150 s
    fault_window_s: float = field(default=0.0, metadata=_rng(0.0))
    fault_contradiction: float = field(default=0.1, metadata=_rng(0.0, 1.0))  # a lost call opens it from this
    fault_turn_max: float = field(default=0.0, metadata=_rng(0.0))  # rad/s: cap on p_k's heading std per s (0: none)
    fault_shift_max: float = field(default=1.5, metadata=_rng(0.0))  # m/s: cap on p_k's translation std per s (0: none)
    # a window's first lost updates with the caps
    fault_widen_after: int = field(default=5, metadata=_rng(0, 1_000_000))
    # rad/s: once the track holds again inside the window, p_k's heading std at most this per s (and its translation
    # fault_shift_max's); 0: as while lost
    fault_held_turn_max: float = field(default=0.0, metadata=_rng(0.0))
    # a wheel's slip on every update outside the window (with fault_prob and fault_share): p_k's heading stds this
    # times the step's own turn (up to fault_scale times the model's), its translation the model's. 0: off
    slip_turn: float = field(default=0.0, metadata=_rng(0.0))
    # online odometry scale (mcl.adaptive.OdometryScale): metres of travel its estimate forgets over; 0: off
    scale_window: float = field(default=0.0, metadata=_rng(0.0))
    scale_prior: float = field(default=10.0, metadata=_rng(0.0))  # metres of travel at scale 1 it starts from
    scale_limit: float = field(default=0.15, metadata=_rng(0.0, 0.9))  # the scale stays within 1 +- this


@dataclass(frozen=True, slots=True, kw_only=True)
class LikelihoodFieldConfig:
    """Parameters of likelihood_field_range_finder_model (Prob. Rob. Table 6.3): sensor.likelihood_field."""

    z_hit: float = field(default=0.95, metadata=_rng(0.0, 1.0))
    z_rand: float = field(default=0.05, metadata=_rng(0.0, 1.0))
    sigma_hit: float = field(default=0.1, metadata=_rng(0.0, lo_open=True))  # m
    likelihood_max_dist: float = field(default=2.0, metadata=_rng(0.0, lo_open=True))  # m
    # d inside an occupied region: its depth (to the nearest non-occupied cell, less one cell, less
    # interior_tolerance metres: maps draw walls about a cell thicker than the surface) or zero (AMCL's, the
    # book's as printed)
    interior: Literal["zero", "depth"] = "depth"
    # null: 0.05 m or one cell of the map, whichever is more (mcl.sensors.DEPTH_TOLERANCE); 0 on a map drawn solid
    # (mcl.sensors.drawn_solid)
    interior_tolerance: float | None = field(default=None, metadata=_rng(0.0))  # m
    # depth only: an endpoint deeper than this inside an obstacle scores as this deep (a return from behind furniture
    # moved since the map was made); null (the default): no bound (mcl.sensors._depth_cap)
    interior_cap: float | None = field(default=None, metadata=_rng(0.0))  # m
    # the same choice while the laser is tempered (a global search, or lost recovery spreading poses)
    search_interior: Literal["zero", "depth"] = "zero"
    # ... but with zero, the parts of obstacles at least twice this wide (m) score their depth while searching: a floor
    # plan's black outside, unknown space painted occupied (mcl.maps.OccupancyGrid.solid_regions); 0: off
    search_solid: float = field(default=1.5, metadata=_rng(0.0))
    # where a wall's surface lies in its cells: centre (a SLAM map marks the cell its returns fall in: d from cell
    # centres) or face (a map drawn from a floor plan or CAD, or by mcl simulate: the surface is the cells' edge, d to
    # the faces on both sides; interior_tolerance null is 0 there)
    surface: Literal["centre", "face"] = "centre"
    # negative information: the probability that a beam meeting a mapped obstacle within the laser's reach reads no
    # return (a dropout); each no-return beam whose ray meets one from a pose scores log(no_return_miss) there. 0: off
    # (AMCL's and the book's field leave no-return readings out)
    no_return_miss: float = field(default=0.0, metadata=_rng(0.0, 1.0))
    # the reach of that test, as a fraction of the laser's no-return range (the far end of a laser's range is where a
    # dark or slanted surface first fails to return)
    no_return_reach: float = field(default=0.9, metadata=_rng(0.0, 1.0, lo_open=True))
    # ... only on scans where at least this share of the scored beams read no return (a sparse view: there the few
    # returns leave the pose loose and the no-returns hold it; elsewhere the returns do, and the rays cost time)
    no_return_share: float = field(default=0.5, metadata=_rng(0.0, 1.0))


@dataclass(frozen=True, slots=True, kw_only=True)
class BeamConfig:
    """Parameters of beam_range_finder_model (Prob. Rob. Table 6.1): sensor.beam; the four weights sum to 1."""

    z_hit: float = field(default=0.8, metadata=_rng(0.0, 1.0))
    z_short: float = field(default=0.1, metadata=_rng(0.0, 1.0))  # weight of short readings (unexpected obstacles)
    z_max: float = field(default=0.05, metadata=_rng(0.0, 1.0))  # weight of no-return (max-range) readings
    z_rand: float = field(default=0.05, metadata=_rng(0.0, 1.0))
    sigma_hit: float = field(default=0.1, metadata=_rng(0.0, lo_open=True))  # m
    lambda_short: float = field(default=0.1, metadata=_rng(0.0, lo_open=True))  # 1/m, rate of p_short
    beam_lut: bool = False  # gather expected ranges from a precomputed (x, y, theta) table instead of casting
    beam_lut_bins: int = field(default=120, metadata=_rng(4, 4096))  # heading bins of that table


# The flat keys of the sensor section before each model had its own block (issue 11): rejected with the new place.
MOVED_SENSOR_KEYS = {
    k: " or ".join(f"sensor.{m}.{k}" for m, c in (("likelihood_field", LikelihoodFieldConfig), ("beam", BeamConfig))
                   if k in c.__dataclass_fields__)
    for k in ("z_hit", "z_rand", "sigma_hit", "likelihood_max_dist", "z_short", "z_max", "lambda_short", "beam_lut",
              "beam_lut_bins")
}


@dataclass(frozen=True, slots=True, kw_only=True)
class SensorConfig:
    """Range finder model: likelihood field (Prob. Rob. Table 6.3) or beam model (Table 6.1).

    Each model has its own block of parameters (``likelihood_field``, ``beam``) with working defaults, so
    switching ``model`` is one key. ``mcl calibrate sensor`` fits them (Table 6.2, learn_intrinsic_parameters).
    The sensor models read :func:`sensor_model_view`: the common keys plus the chosen model's block.
    """

    use: bool = True  # false: the laser is not used (landmark-only runs, landmarks.use: true)
    model: Literal["likelihood_field", "beam"] = "likelihood_field"
    likelihood_field: LikelihoodFieldConfig = field(default_factory=LikelihoodFieldConfig)
    beam: BeamConfig = field(default_factory=BeamConfig)
    max_beams: int = field(default=60, metadata=_rng(1, 100_000))
    range_min: float = field(default=0.0, metadata=_rng(0.0))
    range_max: float = field(default=80.0, metadata=_rng(0.0, lo_open=True))  # readings >= this: no return
    time_offset: float = field(default=0.0, metadata=_rng(-1e10, 1e10))  # s added to each scan's stamp
    # the scans' stamps late or early by an offset the check before the run finds (mcl.latency): fit (each scan
    # paired with the odometry at the time found, on top of time_offset; a warning) or keep (a warning only)
    stamp_offset: Literal["fit", "keep"] = "fit"
    # deskewing: s from a scan's first beam to its last (beams in array order, the first at the stamp); each endpoint
    # is moved by the robot's motion (from the odometry) since the stamp. auto: the input's own beam times (a bag's
    # LaserScan time_increment; a CARMEN log gives none); 0: off
    sweep_time: float | Literal["auto"] = field(default="auto", metadata=_rng(0.0, 1.0))
    exponent: float = field(default=1.0, metadata=_rng(0.0, 1.0, lo_open=True))  # temper the beam product
    # beam skipping (after AMCL likelihood_field_prob): once converged, ignore the short beams most particles cannot
    # explain (AMCL's own settings: beam_skip_distance 0.5, beam_skip_threshold 0.3, beam_skip_rule amcl)
    beam_skip: bool = False
    beam_skip_distance: float = field(default=0.25, metadata=_rng(0.0, lo_open=True))  # m: endpoint explained if closer
    beam_skip_threshold: float = field(default=0.5, metadata=_rng(0.0, 1.0))  # keep a beam explained by > this fraction
    beam_skip_error_threshold: float = field(default=0.9, metadata=_rng(0.0, 1.0))  # skip >= this fraction: use all
    # short: skip only unexplained beams that end in free space in front of the map (unmapped obstacles only shorten
    # readings; a beam through a mapped wall says the pose is wrong); amcl: every unexplained beam, as AMCL
    beam_skip_rule: Literal["short", "amcl"] = "short"
    # unmapped objects (mcl.sensors.UnmappedObjects): while tracking, skip the beams of small segments of the scan
    # (people, chairs) whose endpoints, seen from the estimate, lie off every mapped obstacle
    unmapped_skip: bool = True
    unmapped_width: float = field(default=1.2, metadata=_rng(0.0, lo_open=True))  # m: segments narrower than this
    unmapped_jump: float = field(default=0.3, metadata=_rng(0.0, lo_open=True))  # m: a range step this big splits
    unmapped_distance: float = field(default=0.3, metadata=_rng(0.0))  # m: skipped only if this far from the map
    unmapped_spread: float = field(default=2.0, metadata=_rng(0.0))  # ... unless a forward shift (std) fits them
    # ... and on a turning step, not unless farther than this many std of the heading noise the turn adds times the
    # endpoint's range (0: off)
    unmapped_turn_sigmas: float = field(default=0.5, metadata=_rng(0.0))
    unmapped_fit: float = field(default=0.9, metadata=_rng(-2.0, 1.0))  # the rest of the scan must fit this well
    unmapped_after: int = field(default=50, metadata=_rng(0, 1_000_000))  # updates since a lost call before any skip
    unmapped_unknown: bool = True  # while tracking, skip beams running over unknown cells only (a region never mapped)
    unmapped_blind: bool = True  # every return off the map and no mapped obstacle in the laser's view: predict only
    laser_pose: tuple[float, float, float] | None = None  # mounting pose in the robot frame; null -> from the log
    # leave out the beams that read the robot itself (a wheel, a mast: the same short range on every scan, also while
    # the robot turns), found in the log before the run (mcl.datasets.selfhits) and said in a note
    self_hit_skip: bool = True
    # lasers fused (an AGV's front and rear): one whose scans fit the odometry only turned from its mounting or
    # mirrored, while another's fit it as recorded (its /tf turned half a turn, upside down), found before the run
    # (mcl.odomcheck): leave_out (its scans not weighed; a warning) or keep (a warning only)
    misfit_laser: Literal["leave_out", "keep"] = "leave_out"
    # the laser's scans fit the odometry best with it turned a few degrees from its mounting (2 or more, and 4 standard
    # errors; found before the run, mcl.odomcheck): fit (the run mounts it so; a warning) or keep (a warning only)
    mount_yaw: Literal["fit", "keep"] = "fit"
    # the laser is mounted upside down and the log or the bag's /tf does not say so: every scan is read mirrored (a
    # beam at angle a points at -a); mcl.odomcheck's warning of reversed turns is the sign
    upside_down: bool = False


@dataclass(frozen=True, slots=True, kw_only=True)
class RerunConfig:
    """What goes into the Rerun recording."""

    mode: Literal["save", "spawn", "serve", "off"] = "save"
    particles_max: int = field(default=1000, metadata=_rng(0, 10_000_000))  # particles logged per step
    particles_every: int = field(default=1, metadata=_rng(1, 1_000_000))  # log the cloud every k-th update
    # MB: a log long enough to take the recording past this logs the cloud on fewer updates (mcl run raises
    # particles_every and says so); the map layers come on top. 0: no budget
    budget_mb: float = field(default=0.0, metadata=_rng(0.0))
    scan: bool = True  # log the scan endpoints seen from the estimate
    lines: bool = False  # extract line features from each scan (mcl.features, split-and-merge) and log them


@dataclass(frozen=True, slots=True, kw_only=True)
class EvalConfig:
    """How `mcl eval` and a run with truth score a trajectory."""

    converged_within: float = field(default=0.3, metadata=_rng(0.0, lo_open=True))  # m, for convergence time
    # s: at the first update at or after this time the filter is kidnapped: its particles replaced by a cloud around
    # a free pose at least kidnap_m from the truth there (a recovery test on a real log; mcl eval's kidnapped mode
    # sets it, so a run folder's config.yaml repeats the run); null: not
    kidnap_at: float | None = field(default=None, metadata=_rng(0.0))
    kidnap_m: float = field(default=5.0, metadata=_rng(0.0, lo_open=True))  # m


@dataclass(frozen=True, slots=True, kw_only=True)
class LandmarkConfig:
    """Range-bearing landmarks with known correspondences (Prob. Rob. Table 6.4,
    landmark_model_known_correspondence, with a false-positive mixture; mcl.landmarks)."""

    use: bool = False  # correct with the log's LANDMARK observations
    map: str | None = None  # landmark map YAML (landmarks: [{id, x, y}, ...])
    sigma_range: float = field(default=0.1, metadata=_rng(0.0, lo_open=True))  # m
    sigma_bearing: float = field(default=0.05, metadata=_rng(0.0, lo_open=True))  # rad
    z_det: float = field(default=0.95, metadata=_rng(0.0, 1.0))  # weight of p_det
    z_fp: float = field(default=0.05, metadata=_rng(0.0, 1.0))  # weight of false positives, uniform density
    range_max: float = field(default=10.0, metadata=_rng(0.0, lo_open=True))  # m: p_uniform = 1/(range_max 2 pi)


@dataclass(frozen=True, slots=True, kw_only=True)
class PlaneConfig:
    """Plane features from a depth camera (seed 003, "Kinect Features (Plane)"; mcl.planes): extraction by
    the randomized Hough transform (or RANSAC) and a measurement model against a map of vertical faces."""

    use: bool = False  # correct with the planes of the depth frames in ``depth``
    depth: str | None = None  # depth folder: camera.yaml and <t>.npz frames (mcl simulate --depth writes one)
    map: str | None = None  # plane map YAML (planes: [{x0, y0, x1, y1}, ...]); null: faces of the occupancy grid
    method: Literal["rht", "ransac"] = "rht"
    stride: int = field(default=4, metadata=_rng(1, 64))  # use every stride-th row and column of the image
    max_planes: int = field(default=8, metadata=_rng(1, 64))  # the seed's DetectedPlanes < 8
    min_points: int = field(default=200, metadata=_rng(3, 10**7))  # the seed's MinPoints: stop when as few remain
    min_inliers: int = field(default=100, metadata=_rng(3, 10**7))  # a plane needs this many points
    votes: int = field(default=10, metadata=_rng(1, 10**6))  # votes in a Hough cell that make a local maximum
    region_px: float = field(default=15.0, metadata=_rng(1.0, 10_000.0))  # radius of the random circular region
    theta_bins: int = field(default=45, metadata=_rng(3, 3600))  # Hough cells over theta in [0, pi]
    phi_bins: int = field(default=90, metadata=_rng(3, 7200))  # Hough cells over phi in [-pi, pi)
    rho_step: float = field(default=0.05, metadata=_rng(0.0, lo_open=True))  # m: Hough cell size in rho
    max_trials: int = field(default=3000, metadata=_rng(1, 10**7))  # random triples per cloud at most
    ransac_iterations: int = field(default=150, metadata=_rng(1, 10**6))  # triples per plane (method ransac)
    k_sigma: float = field(default=3.0, metadata=_rng(0.0, lo_open=True))  # inliers: within k residual stds
    coarse: float = field(default=0.05, metadata=_rng(0.0, lo_open=True))  # m: first inlier band of a candidate
    erode: int = field(default=2, metadata=_rng(0, 50))  # pixels of each plane's border left out of its fit
    vertical_tol: float = field(default=0.1, metadata=_rng(0.0, math.pi / 2, lo_open=True))  # rad: a wall
    sigma_phi: float = field(default=0.03, metadata=_rng(0.0, lo_open=True))  # rad: map/model noise added to the fit's
    sigma_rho: float = field(default=0.05, metadata=_rng(0.0, lo_open=True))  # m
    z_det: float = field(default=0.9, metadata=_rng(0.0, 1.0))  # weight of p_det
    z_fp: float = field(default=0.1, metadata=_rng(0.0, 1.0))  # weight of false positives, uniform density
    range_max: float = field(default=4.5, metadata=_rng(0.0, lo_open=True))  # m: p_uniform = 1/(2 pi range_max)
    gate: float = field(default=3.0, metadata=_rng(0.0, lo_open=True))  # Mahalanobis distance of an association
    extent_margin: float = field(default=0.3, metadata=_rng(0.0))  # m: a patch centre may lie this far off a face


@dataclass(frozen=True, slots=True, kw_only=True)
class QualityConfig:
    """The localization-quality signal and the lost belief (mcl.quality)."""

    distance: float = field(default=0.3, metadata=_rng(0.0, lo_open=True))  # m: a beam matches the map within this
    # an update is bad when match - 2 contradiction < this
    lost_below: float = field(default=0.6, metadata=_rng(-2.0, 1.0))
    # lost when this many of the last 2k-1 updates were bad
    lost_after: int = field(default=3, metadata=_rng(1, 10_000))
    # ... or at once when one update's score is below this (-2: never, no score is lower)
    lost_at_once_below: float = field(default=-2.0, metadata=_rng(-2.0, 1.0))
    # such a call on a track whose last 2 lost_after - 1 scores were all at least this is a collapse (a kidnap's
    # signature): lost recovery re-seeds globally at once, unprotected (> 1: never)
    collapse_from: float = field(default=2.0, metadata=_rng(-2.0, 2.0))
    min_beams: int = field(default=5, metadata=_rng(1, 100_000))  # a fit of fewer beams with a return is no evidence
    # ... and on a track from a known pose not yet believed lost a fit of fewer than this (at most a quarter of
    # sensor.max_beams) is no evidence for the lost belief (mcl.quality.ScanQuality._evidence_beams); 0: min_beams
    held_min_beams: int = field(default=0, metadata=_rng(0, 100_000))
    # ... and such sparse fits (min_beams returns or more) count together once they hold this many returns, as one
    # fit weighted by returns (mcl.quality.ScanQuality._pooled); 0: they are no evidence
    held_pool_beams: int = field(default=0, metadata=_rng(0, 100_000))
    # ... and a track from a known pose is held again (those two bars back) after this many updates without a lost
    # call since its last lost episode (mcl.quality.ScanQuality.update); 0: never, once believed lost
    held_again: int = field(default=0, metadata=_rng(0, 100_000))
    # a scan with no beam through a mapped wall is bad only below this (when lower than lost_below): readings short
    # of the map are what people and furniture the map lacks give; 1.0: no such rule
    occluded_below: float = field(default=1.0, metadata=_rng(-2.0, 1.0))
    # ... and below it too, such a scan is no evidence in a sparse view (the map shows the laser obstacles in at most
    # half its scored directions, cast from the estimate to its reach) while at most this share of them read nothing
    # there or past them, or when the map shows it fewer than min_beams: people hide what the map shows, a wrong
    # place lacks it (< 0: off)
    occluded_missing: float = field(default=-1.0, metadata=_rng(-1.0, 1.0))
    # ... but not while more of its returns lie on open floor (neither matched nor through a wall) than this share of
    # its scored directions: people fill a few, a wrong place's own walls most (1.0: no such cap)
    occluded_open: float = field(default=1.0, metadata=_rng(0.0, 1.0))
    # ... and so is a scan whose beams through walls all end within this of a mapped obstacle (m; 0: none is
    # exempt): near misses, as an estimate a few decimetres off makes them; only its match counts then
    occluded_depth: float = field(default=0.0, metadata=_rng(0.0, 100.0))
    # ... while no score of the last 2 lost_after - 1 updates reached this (occlusion creeps in; > 1: always), on a
    # track not lost within doubt_updates updates
    occluded_prior: float = field(default=2.0, metadata=_rng(-2.0, 2.0))
    # an update is bad also when this share of its beams or more went through mapped walls (0: off)
    contradiction_above: float = field(default=0.0, metadata=_rng(0.0, 1.0))
    # a lost scan that matches under this share (or goes through walls, contradiction_above) refutes the estimate:
    # filter.recovery_wait does not wait for it (0: only through walls)
    occlusion_match: float = field(default=0.0, metadata=_rng(0.0, 1.0))
    # a scan narrower than 180 degrees (a depth camera's): occluded_below and occlusion_match times fov / 180 degrees,
    # occluded_depth times its square root and occluded_prior over it (scaled; one person fills a third of a
    # 59-degree view), or as given (same)
    narrow_view: Literal["scaled", "same"] = "scaled"
    doubt_margin: float = field(default=0.25, metadata=_rng(0.0, 2.0))  # after a lost episode: bad also this far below
    # the score the track had before it (0: off)
    doubt_updates: int = field(default=50, metadata=_rng(1, 100_000))  # ... for this many updates after the episode


@dataclass(frozen=True, slots=True, kw_only=True)
class TopicsConfig:
    """What mcl reads from a ROS bag (mcl.datasets.rosbag); topic names as in the bag."""

    # auto (/scan, else the only LaserScan / MultiEchoLaserScan, else the level fixed ones), all (fuse every scan
    # topic), or a topic name
    scan: str = "auto"
    odom: str = "auto"  # auto (/odom, else the only Odometry topic, else /tf, else laser), tf, laser, or a topic
    map: str | None = "/map"  # nav_msgs/OccupancyGrid used when no map file is given; null: never
    initial_pose: str | None = "/initialpose"  # first PoseWithCovarianceStamped starts tracking; null: ignore
    truth: str | None = None  # PoseStamped, PoseWithCovarianceStamped or Odometry topic with reference poses
    cloud_z: tuple[float, float] = (-0.1, 0.1)  # PointCloud2: z band (m, in the cloud's frame) kept as a plane
    cloud_beams: int = field(default=720, metadata=_rng(8, 100_000))  # PointCloud2: bearing bins over 360 deg
    echo: Literal["first", "last"] = "first"  # MultiEchoLaserScan: the return read per beam (first: the nearest)


@dataclass(frozen=True, slots=True, kw_only=True)
class FramesConfig:
    """tf frame names (REP 105) for a ROS bag."""

    odom: str = "odom"  # odometry frame: /tf odom -> base gives the odometry when no Odometry topic is used
    base: str = "base_link"  # robot frame: the laser's mounting is base -> the scan's frame


@dataclass(frozen=True, slots=True, kw_only=True)
class Config:
    """A whole run: the data, the seed and each part of the filter."""

    map: str | None = None
    log: str | None = None
    bag: str | None = None  # ROS bag (.bag, .db3, .mcap or a rosbag2 folder) instead of a CARMEN log
    truth: str | None = None
    # which laser stream of the log: auto (FLASER, with RLASER fused when both; else ROBOTLASER1, with ROBOTLASER2
    # fused when both), FLASER, RLASER, ROBOTLASER1, ROBOTLASER2, RAWLASER1..4, or several fused (FLASER,RLASER)
    laser: str = "auto"
    seed: int = field(default=1, metadata=_rng(0, 2**63 - 1))
    filter: FilterConfig = field(default_factory=FilterConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    rerun: RerunConfig = field(default_factory=RerunConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    landmarks: LandmarkConfig = field(default_factory=LandmarkConfig)
    planes: PlaneConfig = field(default_factory=PlaneConfig)
    quality: QualityConfig = field(default_factory=QualityConfig)
    topics: TopicsConfig = field(default_factory=TopicsConfig)
    frames: FramesConfig = field(default_factory=FramesConfig)


LASER_KINDS = ("auto", "FLASER", "RLASER", "ROBOTLASER1", "ROBOTLASER2", "RAWLASER1", "RAWLASER2", "RAWLASER3",
               "RAWLASER4")
PATH_KEYS = ("map", "log", "bag", "truth")


def sensor_model_view(s: Any, model: str | None = None) -> Any:
    """The keys a range finder model reads, flat: the sensor section's common keys plus the block of ``model``
    (default ``s.model``). Anything else (a namespace with the keys already flat) is returned as it is."""
    if not isinstance(s, SensorConfig):
        return s
    model = model or s.model
    block = getattr(s, model)
    common = {f.name: getattr(s, f.name) for f in dataclasses.fields(s) if f.name not in ("likelihood_field", "beam")}
    common["model"] = model
    return types.SimpleNamespace(**common, **{f.name: getattr(block, f.name) for f in dataclasses.fields(block)})


# ----------------------------------------------------------------------------- validation


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(tp))
    if origin in (types.UnionType, typing.Union):
        return " or ".join(_type_name(a) for a in typing.get_args(tp))
    if origin is tuple:
        return f"a list of {len(typing.get_args(tp))} numbers"
    if tp is type(None):
        return "null"
    return {float: "a number", int: "an integer", bool: "true or false", str: "a string"}.get(tp, str(tp))


# An integer in exponent notation ("5e3", "1E4"): what a float key takes (mcl.yamlfile.finite_number), an integer
# key too when it is whole
_EXPONENT_INT = re.compile(r"[-+]?[0-9]+(?:\.[0-9]*)?[eE][-+]?[0-9]+")


def _shown(value: Any) -> str:
    """A config value as an error message shows it: as YAML spells true, false and null, else a repr cut to one
    short line (a 100,000-number list was a 500 kB error line)."""
    if value is None or isinstance(value, bool):
        return yaml.safe_dump(value).split("\n", 1)[0]
    return short_repr(value, 60)


def _coerce(value: Any, tp: Any, key: str) -> Any:
    """Check `value` against the annotation `tp`; return it converted (ints to floats, lists to tuples)."""
    origin = typing.get_origin(tp)
    if origin in (types.UnionType, typing.Union):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        others = [a for a in args if a is not type(None)]
        if len(others) == 1 and value is not None:  # "X or null" given something else: the error of X itself
            return _coerce(value, others[0], key)  # (filter.initial_pose[0]: expected a finite number, got 'nan')
        for a in others:
            try:
                return _coerce(value, a, key)
            except ConfigError:
                pass
        raise ConfigError(f"{key}: expected {_type_name(tp)}, got {_shown(value)}")
    if origin is Literal:
        choices = typing.get_args(tp)
        if isinstance(value, bool):
            # YAML 1.1 reads a bare off/no as false and on/yes as true: map back to the choice meant.
            spelled = [c for c in choices if c in (("on", "yes", "true") if value else ("off", "no", "false"))]
            if len(spelled) == 1:
                value = spelled[0]
        if value not in choices:
            hint = difflib.get_close_matches(str(value), [str(c) for c in choices], n=1)
            extra = f" (did you mean {hint[0]}?)" if hint else ""
            raise ConfigError(f"{key}: expected {_type_name(tp)}, got {_shown(value)}{extra}")
        return value
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)) or len(value) != len(args):
            raise ConfigError(f"{key}: expected {_type_name(tp)}, got {_shown(value)}")
        return tuple(_coerce(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {_shown(value)}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, str) and _EXPONENT_INT.fullmatch(value.strip()):  # 5e3: a string to YAML 1.1
                value = float(value)
            if isinstance(value, float) and value.is_integer():
                return int(value)
            raise ConfigError(f"{key}: expected an integer, got {_shown(value)}")
        return value
    if tp is float:
        return finite_number(value, key, ConfigError)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {_shown(value)}")
        return value
    raise ConfigError(f"{key}: unsupported type {tp}")  # pragma: no cover - a bug in the dataclasses


def _check_range(value: Any, meta: dict, key: str) -> None:
    if "range" not in meta or value is None or isinstance(value, str):
        return
    lo, hi, lo_open, hi_open = meta["range"]
    if lo is not None and (value < lo or (lo_open and value == lo)):
        raise ConfigError(f"{key}: {value!r} is out of range (must be {'>' if lo_open else '>='} {lo})")
    if hi is not None and (value > hi or (hi_open and value == hi)):
        raise ConfigError(f"{key}: {value!r} is out of range (must be {'<' if hi_open else '<='} {hi})")


def _build(cls: type, data: Any, prefix: str) -> Any:
    """Build dataclass `cls` from a mapping, validating every key."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{prefix.rstrip('.') or 'config'}: expected a mapping, got {_shown(data)}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs = {}
    for k, v in data.items():
        key = f"{prefix}{_printable(k)}"
        if k not in fields:
            if cls is SensorConfig and k in MOVED_SENSOR_KEYS:
                raise ConfigError(f"{key}: moved to {MOVED_SENSOR_KEYS[k]}")
            # a key's exact home elsewhere first (`filter.laser_pose` was "did you mean cluster_size?"), then a
            # near miss here
            extra = _elsewhere(str(k), prefix)
            hint = [] if extra or "." in str(k) else difflib.get_close_matches(str(k), list(fields), n=1)
            extra = extra or (f" (did you mean {hint[0]}?)" if hint else "")
            raise ConfigError(f"{key}: unknown key{extra}")
        tp = hints[k]
        if dataclasses.is_dataclass(tp):
            kwargs[k] = _build(tp, v, key + ".")
        else:
            kwargs[k] = _coerce(v, tp, key)
            _check_range(kwargs[k], fields[k].metadata, key)
    return cls(**kwargs)


def _keys_of(cls: type, prefix: str = "") -> list[str]:
    """Every dotted key of the dataclass ``cls`` (sections' keys included)."""
    keys = []
    for name, tp in typing.get_type_hints(cls).items():
        keys.append(prefix + name)
        if dataclasses.is_dataclass(tp):
            keys += _keys_of(tp, f"{prefix}{name}.")
    return keys


def _elsewhere(k: str, prefix: str) -> str:
    """The hint for a key unknown where it stands but known elsewhere: a dotted key copied from --set into a file
    (``filter.particles: 100``), or a key in the wrong section (``particles`` at the top, ``filter.alpha1``)."""
    keys = _keys_of(Config)
    if f"{prefix}{k}" in keys:  # "filter.particles" written as one key under the top level
        parts = k.split(".")
        return (f" (dotted keys are --set's; in a file, nest it: {parts[0]}:, then "
                + ", then ".join(f"{p}: indented under it" for p in parts[1:]) + ")")
    homes = [key for key in keys if key.rsplit(".", 1)[-1] == k and not dataclasses.is_dataclass(_key_type(key))]
    if homes:
        return f" (it belongs in {' or '.join(homes[:3])})"
    return ""


def _key_type(dotted: str) -> Any:
    tp: Any = Config
    for part in dotted.split("."):
        tp = typing.get_type_hints(tp)[part]
    return tp


class _CrossCheckError(ConfigError):
    """A check across keys failed; ``keys``: every key it read, the message's own first (load_config names the
    --set that gave one of them)."""

    def __init__(self, message: str, *others: str):
        super().__init__(message)
        self.keys = (message.split(":", 1)[0], *others)


def _cross_checks(cfg: Config) -> None:
    kinds = str(cfg.laser).split(",")
    if cfg.laser not in LASER_KINDS and not (len(kinds) > 1 and len(set(kinds)) == len(kinds)
                                             and all(k in LASER_KINDS[1:] for k in kinds)):
        raise _CrossCheckError(f"laser: expected one of {', '.join(LASER_KINDS)}, or several of them fused, comma "
                               f"separated (FLASER,RLASER), got {cfg.laser!r}")
    if cfg.log is not None and cfg.bag is not None:
        raise _CrossCheckError("bag: give a CARMEN log (log) or a ROS bag (bag), not both", "log")
    if cfg.log is not None:
        from mcl.datasets.rosbag import is_bag

        if is_bag(cfg.log):
            raise _CrossCheckError(f"log: {cfg.log} is a ROS bag: give it as bag (--bag on the command line)")
    for section in (cfg.topics, cfg.sensor, cfg.landmarks, cfg.planes):
        _section_checks(section)
    s, lm, pc = cfg.sensor, cfg.landmarks, cfg.planes
    if not s.use and not lm.use and not pc.use:
        raise _CrossCheckError("sensor.use: false needs landmarks.use: true or planes.use: true (nothing else to "
                               "correct with)", "landmarks.use", "planes.use")
    if cfg.quality.min_beams > s.max_beams:
        raise _CrossCheckError(f"quality.min_beams: {cfg.quality.min_beams} is more than sensor.max_beams "
                               f"({s.max_beams}): no update would have beams enough to judge", "sensor.max_beams")
    _section_checks(cfg.filter)


def _section_checks(sec: Any) -> None:
    """The checks across the keys of one section (``_cross_checks`` runs them for a whole Config, ``replace`` for
    the section it changes: the beam weights of ``replace(cfg.sensor.beam, z_hit=0.5)`` went unchecked, and the
    model scored with a mixture of total mass 0.7)."""
    if isinstance(sec, TopicsConfig):
        if not sec.cloud_z[0] <= sec.cloud_z[1]:
            raise _CrossCheckError(f"topics.cloud_z: expected [min, max], got {list(sec.cloud_z)}")
        if sec.scan == "" or sec.odom == "":
            raise _CrossCheckError("topics.scan: empty topic name", "topics.odom")
    elif isinstance(sec, SensorConfig):
        if sec.range_min >= sec.range_max:
            raise _CrossCheckError(f"sensor.range_min: {sec.range_min} must be below sensor.range_max "
                                   f"({sec.range_max})", "sensor.range_max")
        _section_checks(sec.likelihood_field)
        if sec.use and sec.model == "likelihood_field" and sec.likelihood_field.z_hit <= 0:  # every pose alike
            raise _CrossCheckError("sensor.likelihood_field.z_hit: 0 makes every pose score alike (the scan would "
                                   "correct nothing); for a run without the laser set sensor.use: false",
                                   "sensor.model", "sensor.use")
        _section_checks(sec.beam)
    elif isinstance(sec, LikelihoodFieldConfig):
        if sec.z_hit + sec.z_rand <= 0:
            raise _CrossCheckError("sensor.likelihood_field.z_hit: z_hit + z_rand must be positive",
                                   "sensor.likelihood_field.z_rand")
    elif isinstance(sec, BeamConfig):
        total = sec.z_hit + sec.z_short + sec.z_max + sec.z_rand
        if abs(total - 1.0) > 1e-6:
            raise _CrossCheckError(
                f"sensor.beam.z_hit: the beam model's mixture weights z_hit + z_short + z_max + z_rand must sum to "
                f"1, got {sec.z_hit:g} + {sec.z_short:g} + {sec.z_max:g} + {sec.z_rand:g} = {total:g} (the "
                f"defaults: 0.8, 0.1, 0.05, 0.05)", "sensor.beam.z_short", "sensor.beam.z_max", "sensor.beam.z_rand"
            )
    elif isinstance(sec, LandmarkConfig):
        if sec.z_det + sec.z_fp <= 0:
            raise _CrossCheckError("landmarks.z_det: z_det + z_fp must be positive", "landmarks.z_fp")
        if sec.use and sec.z_det <= 0:  # as sensor.likelihood_field.z_hit 0: every pose alike
            raise _CrossCheckError("landmarks.z_det: 0 makes every pose score alike (the landmarks would correct "
                                   "nothing); for a run without them set landmarks.use: false", "landmarks.use")
        if sec.use and sec.map is None:
            raise _CrossCheckError("landmarks.map: landmarks.use is true but no landmark map is given",
                                   "landmarks.use")
    elif isinstance(sec, PlaneConfig):
        if sec.z_det + sec.z_fp <= 0:
            raise _CrossCheckError("planes.z_det: z_det + z_fp must be positive", "planes.z_fp")
        if sec.use and sec.z_det <= 0:
            raise _CrossCheckError("planes.z_det: 0 makes every pose score alike (the planes would correct "
                                   "nothing); for a run without them set planes.use: false", "planes.use")
        if sec.use and sec.depth is None:
            raise _CrossCheckError("planes.depth: planes.use is true but no depth folder is given", "planes.use")
    elif isinstance(sec, FilterConfig):
        if any(v < 0 for v in sec.initial_std):
            raise _CrossCheckError("filter.initial_std: standard deviations must be >= 0")
        if any(not v > 0 for v in sec.respread_std):
            raise _CrossCheckError("filter.respread_std: standard deviations must be > 0")
        if any(not v > 0 for v in sec.recovery_local_std):
            raise _CrossCheckError("filter.recovery_local_std: standard deviations must be > 0")
        if sec.recovery in (True, "augmented", "auto") and sec.recovery_alpha_slow >= sec.recovery_alpha_fast:
            raise _CrossCheckError(
                f"filter.recovery_alpha_slow: {sec.recovery_alpha_slow} must be below filter.recovery_alpha_fast "
                f"({sec.recovery_alpha_fast})", "filter.recovery", "filter.recovery_alpha_fast"
            )


# ----------------------------------------------------------------------------- overrides and paths


def _printable(k: Any) -> str:
    """A key or override as it goes into a one-line message: control characters escaped."""
    s = str(k)
    return s if s.isprintable() else repr(s)[1:-1]


def _cut(text: str, limit: int = 240) -> str:
    """A --set as an error line quotes it: whole up to ``limit`` characters (a path in it is the user's to see),
    cut beyond (a 5,000-digit seed was a 5 kB line)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def parse_override(text: str) -> tuple[list[str], Any]:
    """``section.key=value`` -> (["section", "key"], parsed YAML value)."""
    if "=" not in text:
        raise ConfigError(f"--set {_printable(text)}: expected section.key=value")
    key, raw = text.split("=", 1)
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise ConfigError(f"--set {_printable(text)}: expected section.key=value")
    try:
        value = load_text(raw) if raw.strip() else None
    except yaml.YAMLError:
        value = raw
    return key.split("."), value


def _related(a: str, b: str) -> bool:
    """Whether dotted keys ``a`` and ``b`` are one key or one holds the other (a section, a list's item)."""
    if len(a) > len(b):
        a, b = b, a
    return b == a or (b.startswith(a) and b[len(a)] in ".[")


# the data a config names, relative to its own folder: never taken from default.yaml (its demo's files)
DATA_KEYS = (*PATH_KEYS, "laser", "landmarks.map", "planes.depth", "planes.map")


def _at_line(path: Path, error: str) -> str:
    """``path``, or ``path:LINE`` when ``error`` begins with a dotted key the file gives (its line): "my.yaml:12:
    filter.particels: unknown key (did you mean particles?)". A key only default.yaml gives has no line here."""
    from mcl.yamlfile import key_line

    key = error.split(":", 1)[0].strip()
    if not key or " " in key:
        return str(path)
    line = key_line(path, key.split("[", 1)[0])
    return f"{path}:{line}" if line is not None else str(path)


def _over_defaults(loaded: dict, path: Path) -> dict:
    """A config file's keys laid over ``configs/default.yaml``'s (the documented, corpus-chosen defaults), so that
    a key the file does not give takes the value default.yaml shows, not the code's plain one (a file with a map
    and a log alone ran a fixed 5,000 particles, no recovery); the data keys (``DATA_KEYS``) are the file's own.
    default.yaml itself, and a file that is not a mapping, as they are."""
    default = shipped("configs/default.yaml")
    if not isinstance(loaded, dict) or not default.exists() or path.resolve() == default.resolve():
        return loaded
    base = read_yaml(default, ConfigError) or {}
    for key in DATA_KEYS:
        *sections, leaf = key.split(".")
        node = base
        for sec in sections:
            node = node.get(sec) if isinstance(node, dict) else None
        if isinstance(node, dict):
            node.pop(leaf, None)

    def merge(into: dict, over: dict) -> dict:
        for k, v in over.items():
            if v is None and isinstance(into.get(k), dict):  # `filter:` with every key commented out: no change
                continue  # (it was the code's plain values: 5,000 particles, no KLD, no recovery, with no word)
            into[k] = merge(into[k], v) if isinstance(v, dict) and isinstance(into.get(k), dict) else v
        return into

    return merge(base, loaded)


def _apply(data: dict, path: list[str], value: Any) -> None:
    node = data
    for i, part in enumerate(path[:-1]):
        nxt = node.get(part)
        if nxt is None:
            nxt = node[part] = {}
        if not isinstance(nxt, dict):
            raise ConfigError(f"{_printable('.'.join(path[: i + 1]))}: is not a section")
        node = nxt
    if isinstance(node.get(path[-1]), dict) and (value is None or isinstance(value, dict)):
        # a section given whole (`--set filter={}`, `--set filter=null`): its keys over the section's, none dropped
        if value is None:
            raise ConfigError(f"{_printable('.'.join(path))}: is a section: set its keys ({_printable(path[-1])}.KEY="
                              "VALUE)")
        for k, v in value.items():
            _apply(node, [path[-1], str(k)], v)
        return
    node[path[-1]] = value


def _resolve_path(value: str | None, base: Path | None) -> str | None:
    if value is None:
        return None
    p = Path(value).expanduser()
    if p.is_absolute():
        return str(p)
    # ... and the default config's folder: a copy of it (`mcl config default > my.yaml`) still finds the demo
    candidates = ([base / p] if base is not None else []) + [Path.cwd() / p, PROJECT_ROOT / p,
                                                             shipped("configs") / p]
    for c in candidates:
        if c.exists():
            return str(c.resolve())
    return str(candidates[0].resolve())


# ----------------------------------------------------------------------------- public API


def default_config(overrides: list | tuple = ()) -> Config:
    """``configs/default.yaml`` (the documented, corpus-chosen defaults that ``mcl run`` uses when no config is
    given) with ``key=value`` overrides: what a Python caller wants for "the defaults" (``load_config(None)`` is the
    code's plain filter instead)."""
    return load_config(shipped("configs/default.yaml"), overrides)


def load_config(path: str | Path | None = None, overrides: list | tuple = ()) -> Config:
    """Load and validate a config file with ``key=value`` overrides; its missing keys take ``configs/default.yaml``'s
    values. ``None``: no file, the dataclasses' plain values (a fixed 5,000 particles, no KLD sampling, no recovery:
    the bar of ``configs/baseline.yaml``, not the documented defaults; ``default_config`` gives those).

    An override is the ``--set`` text, or an (option, ``key=value``) pair for a command-line option that sets a
    key (``("--particles 0", "filter.particles=0")``): an error in its value then names the option the user typed.
    """
    data: dict = {}
    base = None
    if path is not None:
        path = Path(path)
        base = path.resolve().parent
        loaded = read_yaml(path, ConfigError)
        if loaded is None:
            loaded = {}
        if not isinstance(loaded, dict):
            raise ConfigError(f"{path}: expected a mapping of sections at the top level")
        data = _over_defaults(loaded, path)
        if overrides:
            # The file on its own first: a bad value in it is an error even when an override replaces it.
            try:
                _build(Config, copy.deepcopy(data), "")
            except ConfigError as e:
                raise ConfigError(f"{_at_line(path, str(e))}: {e}") from None
    set_by: dict[str, str] = {}  # dotted key -> what gave it its value: "--set text", or the option; last given last

    def where(*keys: str) -> str:
        """The prefix of an error about ``keys``: the last --set (or option) that gave one of them, in itself or
        with its section, else the file (none: the defaults)."""
        given = next((w for k, w in reversed(set_by.items()) if any(_related(k, c) for c in keys)), None)
        if given is not None:
            return f"{given}: "
        return f"{_at_line(path, keys[0] if keys else '')}: " if path is not None else ""

    for item in overrides:
        given, text = item if isinstance(item, tuple) else (f"--set {_cut(_printable(item))}", item)
        keys, value = parse_override(text)
        try:
            _apply(data, keys, value)
        except ConfigError as e:
            raise ConfigError(f"{given}: {e}") from None
        key = _printable(".".join(keys))  # as an error message spells it
        set_by.pop(key, None)
        set_by[key] = given
    def base_of(key: str) -> Path | None:
        """A path a --set (or an option) gave is the user's, relative to where they typed it, not to the config's
        folder: --set log=w/x.clf was looked for, and named when missing, as configs/w/x.clf."""
        return None if key in set_by else base

    for k in PATH_KEYS:
        if isinstance(data.get(k), str):
            try:
                data[k] = _resolve_path(data[k], base_of(k))
            except (RuntimeError, ValueError):  # ~user that does not exist; a NUL byte
                raise ConfigError(f"{where(k)}{k}: not a usable path: {data[k]!r}") from None
    for sec, key in (("planes", "depth"), ("planes", "map")):
        if isinstance(data.get(sec), dict) and isinstance(data[sec].get(key), str):
            try:
                data[sec][key] = _resolve_path(data[sec][key], base_of(f"{sec}.{key}"))
            except (RuntimeError, ValueError):
                raise ConfigError(f"{where(f'{sec}.{key}')}{sec}.{key}: not a usable path") from None
    if isinstance(data.get("landmarks"), dict) and isinstance(data["landmarks"].get("map"), str):
        try:
            data["landmarks"]["map"] = _resolve_path(data["landmarks"]["map"], base_of("landmarks.map"))
        except (RuntimeError, ValueError):
            raise ConfigError(f"{where('landmarks.map')}landmarks.map: not a usable path") from None
    # a bad value names where it came from: the --set that gave it (or its section), else the file; a check
    # across keys the last --set among them
    try:
        cfg = _build(Config, data, "")
    except ConfigError as e:
        raise ConfigError(f"{where(str(e).split(':', 1)[0])}{e}") from None
    try:
        _cross_checks(cfg)
    except ConfigError as e:
        raise ConfigError(f"{where(*getattr(e, 'keys', ()))}{e}") from None
    return cfg


def replace(cfg: Any, **changes: Any) -> Any:
    """dataclasses.replace for callers that tweak a config or a section, validated as a config file's keys are
    (ConfigError naming the key): unchecked, ``alpha1=-1`` failed three steps later as "math domain error",
    ``particles=0`` as a ZeroDivisionError. A whole ``Config`` gets the checks across keys too, a section those
    within it (``_section_checks``: the beam weights' sum, range_min below range_max, ...)."""
    new = dataclasses.replace(cfg, **changes)
    hints = typing.get_type_hints(Config)
    prefix = next((f"{name}." for name, tp in hints.items() if tp is type(cfg)), "")
    built = _build(type(new), to_dict(new), prefix)
    if isinstance(built, Config):
        _cross_checks(built)
    else:
        _section_checks(built)
    return built


def to_dict(cfg: Any) -> dict:
    """The config as plain YAML-ready data (tuples become lists)."""

    def conv(v: Any) -> Any:
        if dataclasses.is_dataclass(v):
            return {f.name: conv(getattr(v, f.name)) for f in dataclasses.fields(v)}
        if isinstance(v, tuple):
            return [conv(x) for x in v]
        return v

    return conv(cfg)


def dump_config(cfg: Config) -> str:
    """YAML text of the resolved config; loading it gives back an equal Config."""
    return yaml.safe_dump(to_dict(cfg), sort_keys=False)
