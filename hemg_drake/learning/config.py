"""Settings of learning (the HSMM, eqs. 4-11) and reproduction (eqs. 12-18, 23).
"""

import dataclasses as dc

from hemg_drake.config_fields import checked, key_path

# Alignments of learning.align (learning/align.py).
ALIGNMENTS = ("none", "trim", "dtw")

# HSMM initialisations, reproduction state weightings, trackers and LQR state costs.
HSMM_INITS = ("kmeans", "time", "polyline")
WEIGHTINGS = ("temporal", "spatial", "forward")
TRACKERS = ("gmr", "lqr")
STATE_COSTS = ("active", "mixture")
# Most HSMM states: the paper's tasks take 4, the drawing 18; each state needs at least 8
# samples (pipeline.check_enough_data) and an EM iteration with 100 states on 3 x 1000
# samples takes 0.3 s (measured; 4 states 0.004 s, 18 states 0.09 s).
MAX_STATES = 100
# Most EM iterations: 10x the default; 1000 iterations of the drawing's 18 states on 3000
# samples take about 1.5 min (0.09 s each, measured). The shipped fits converge in fewer.
MAX_ITERATIONS = 1000
# Longest LQR horizon (steps): 10 s planned ahead at the 0.01 s log period. A forward-weighted
# step costs about 33 us per horizon step (measured: 3 ms at 100, 33 ms at 1000, 0.4 s at
# 10 000), so a 5.5 s reproduction (550 steps) takes about 18 s at 1000.
MAX_HORIZON = 1000
# Longest settling before a reproduction (s, simulated): the arm comes to rest in about 1 s.
MAX_SETTLE_TIME = 60.0
# The stiffness the reproduction applies (docs/reproduction.md, "A full stiffness matrix").
STIFFNESS_MODES = ("scalar", "spd")
# Where the reproduction's gain K comes from (the stiffness study, docs/studies.md).
GAIN_SOURCES = ("learnt", "constant", "demonstrated")


@dc.dataclass
class LearningConfig:
    """What the HSMM (eqs. 4-11) learns from the demonstrations, and how it starts."""

    # Number of HSMM states N.
    num_states: int = checked(4, positive=True, maximum=MAX_STATES)
    # Positions of the observations [x, xdot, k]: "tool" (the measured tool point p_WE,
    # v_WE) or "reference" (the reference the CLIK received and its rate: what the slave
    # tracked with the gain k; a pen pressed into the sheet only shows in the reference).
    positions: str = checked("tool", choices=("tool", "reference"))
    # Initial states: "time" (equal times), "kmeans", "polyline" (straight pieces of the
    # path: states start where it turns).
    init: str = checked("kmeans", choices=HSMM_INITS)
    # Covariance floor, relative to each dimension's variance in the data.
    reg_covar: float = checked(1e-2, positive=True)
    # EM iterations at most.
    n_iter: int = checked(100, positive=True, maximum=MAX_ITERATIONS)
    # Fit a task-parameterised HSMM (frames: robot base and scene; learning/tphsmm.py) even
    # when the demonstrations share one placement (it is fitted whenever they do not).
    task_parameterised: bool = checked(False)
    # The TP-HSMM's task frames: "scene" (the scene frame T alone) or "base_and_scene" (the
    # robot's base too, Calinon 2016's product of both). Measured (docs/placements.md): the
    # base frame pulls the drawing's strokes 8 mm towards where the sheet was on average
    # (its Gaussians are no wider than the covariance floor), the scene frame alone 0.5 mm.
    task_frames: str = checked("scene", choices=("scene", "base_and_scene"))
    # How the demonstrations are aligned before the HSMM learns them (learning/align.py):
    # "none" (as recorded), "trim" (each cut to its active span: the idle lead-in and
    # lead-out of a person's takes cut off, docs/learning.md "Learning from natural takes")
    # or "dtw" (each time-warped onto the take of median length by DTW on the positions).
    align: str = checked("none", choices=ALIGNMENTS)


@dc.dataclass
class PushConfig:
    """An external push on the arm during a reproduction (``reproduction.push``): a force at
    the tool point, held for ``duration`` from ``start`` (control/push.py: tau = J^T F on the
    station's ``applied_generalized_force``). Default: none."""

    # The force (N, in the scene frame T); empty: no push.
    force: list[float] = checked([], signed=True, size=(0, 3))
    # When it starts (s after the reproduction starts; the settling before is not pushed).
    start: float = checked(0.0)
    # How long it lasts (s).
    duration: float = checked(0.3, positive=True)


@dc.dataclass
class ReproductionConfig:
    """How the learnt task is reproduced (eqs. 12-18, 23; ``docs/reproduction.md``)."""

    # State weighting h_t: "temporal" (timing alone), "spatial" (eq. 14), "forward"
    # (eqs. 11, 13).
    weighting: str = checked("forward", choices=WEIGHTINGS)
    # kappa of the cross-track attractor (1/s): a start offset decays as exp(-kappa t);
    # 0: eqs. 15-18 alone.
    restoring_gain: float = checked(0.0)
    # The position the "gmr" reproducer observes: "reference" (its own x*) or "tool" (the
    # slave's measured tool point). The "lqr" tracker always re-plans from the tool point.
    observe: str = checked("reference", choices=("reference", "tool"))
    # "gmr": the paper's eqs. 15-18 (GMR velocity integrated by eq. 18; restoring_gain
    # applies to it); "lqr": a receding-horizon LQR tracking the HSMM's states, re-planned
    # from the measured tool point every step (docs/reproduction.md, Trackers), with the
    # temporal or forward weighting.
    tracker: str = checked("gmr", choices=TRACKERS)
    # LQR tracker: steps planned ahead, the control cost r (s^4/m^2), how far its plan may
    # lead the measured tool point (m), and whose precision costs a step: "active" (the
    # most probable state's) or "mixture" (weighted by h).
    horizon: int = checked(100, positive=True, maximum=MAX_HORIZON,
                           why="10 s of 0.01 s steps")  # fmt: skip
    control_cost: float = checked(1.0, positive=True)
    max_lead: float = checked(0.02)
    state_cost: str = checked("active", choices=STATE_COSTS)
    # K_ptr (N/m) and K_dtr (N s/m) of the tracking force (eq. 23; Table I: 50 and 50).
    tracking_gains: list[float] = checked([50.0, 50.0], size=2)
    # The stiffness the station applies: "scalar" (eq. 20: k* scales the joints' stiffness)
    # or "spd" (a Cartesian stiffness at the tool: k* times the shape learnt from the
    # states' position precision, interpolated on the SPD manifold; control/impedance.py).
    stiffness: str = checked("scalar", choices=STIFFNESS_MODES)
    # "spd": the largest ratio of the shape's largest to smallest eigenvalue (>= 1).
    stiffness_ratio: float = checked(10.0, positive=True)
    # "spd": the shape at unit determinant (its geometric mean is eq. 20's harmonic-mean
    # stiffness at the tool) or with its smallest eigenvalue 1 ("softest": the learnt
    # shape only stiffens).
    stiffness_normalisation: str = checked("softest", choices=("determinant", "softest"))
    # Where the gain K comes from: "learnt" (the reproducer's k*, eq. 17: the paper's),
    # "constant" (constant_gain throughout), "demonstrated" (the demonstrations' own K, their
    # time-normalised mean, replayed in time). Clipped to [emg.k_min, emg.k_max] as k* is.
    gain_source: str = checked("learnt", choices=GAIN_SOURCES)
    # "constant": the gain K (> 0).
    constant_gain: float = checked(0.0)
    # An external push on the arm (default: none).
    push: PushConfig = dc.field(default_factory=PushConfig)
    # Simulated time to let the arm come to rest in the scene, holding x*_0, before the
    # reproduction starts (s).
    settle_time: float = checked(1.0, maximum=MAX_SETTLE_TIME)
    # Start offsets (m, in the scene frame T) of the extra reproductions that the full
    # demo runs, each from the demonstrations' mean start plus the offset.
    start_offsets: list[list[float]] = checked([], signed=True)
    # Fresh demonstrations that every reproduction is scored against (out of sample):
    # the full demo records num_heldout of them, seeds heldout_seed .. heldout_seed +
    # num_heldout - 1 (disjoint from the training seeds), at the reproduction's placement
    # (pipeline.demonstrate_heldout); 0: none. The shipped scenarios' seeds are evaluation
    # seeds (hemg_drake/data/seeds.yaml).
    heldout_seed: int = checked(0)
    num_heldout: int = checked(0, maximum=100, why="as num_demonstrations")

    def check(self, key=""):
        """The rules between fields: the "lqr" tracker takes a state-sequence weighting, and
        each start offset is [dx, dy, dz]. Raises ValueError naming the key under ``key``."""
        if self.tracker == "lqr" and self.weighting == "spatial":
            raise ValueError(
                f"key '{key_path(key, 'weighting')}' = 'spatial' does not go with "
                f"'{key_path(key, 'tracker')}' = 'lqr' (it tracks a state sequence: 'temporal' "
                "or 'forward')"
            )
        if self.gain_source == "constant" and not self.constant_gain > 0:
            raise ValueError(
                f"key '{key_path(key, 'constant_gain')}' must be > 0 with "
                f"'{key_path(key, 'gain_source')}' = 'constant', got {self.constant_gain}"
            )
        if self.stiffness_ratio < 1:
            raise ValueError(
                f"key '{key_path(key, 'stiffness_ratio')}' must be >= 1 (largest / smallest "
                f"eigenvalue), got {self.stiffness_ratio}"
            )
        if any(len(offset) != 3 for offset in self.start_offsets):
            raise ValueError(
                f"key '{key_path(key, 'start_offsets')}' must hold [dx, dy, dz] lists, got "
                f"{self.start_offsets}"
            )
