"""A published model of the human arm angle (Kim et al. 2012), calibrated on real reaches.

The synthetic data (:mod:`wholebody.humanlike.synthetic`) need an elbow for every wrist
position. They take it from the redundancy-resolution criterion of

    H. Kim, L. M. Miller, N. Byl, G. M. Abrams, J. Rosen, "Redundancy resolution of the
    human arm and an upper limb exoskeleton", IEEE Trans. Biomed. Eng. 59(6):1770-1779,
    2012 (reported error of the predicted swivel angle below 5 deg in their reaches):

*the arm angle maximises the projection of the major principal axis of the wrist's
manipulability ellipsoid on the unit vector from the wrist to a virtual target on the
head* ("when the elbow is flexed, the palm points to the head").

(The paper's own ref. [22], Zanchettin et al.'s regression of the swivel angle on wrist
position and ZYZ orientation, needs the hand orientation and reference frames the text
does not give, so it is not used.)

Closed form (derived here)
--------------------------
Shoulder ball joint at S, elbow hinge, wrist W, ``D = |W - S|``, ``u = (W - S)/D``. The
elbow lies on a circle about the S-W line: foot point at ``a = (L1^2 - L2^2 + D^2)/(2D)``
from S, radius ``rho = sqrt(L1^2 - a^2)``, unit offset ``p(alpha)``. The wrist Jacobian of
the 4 joints gives ``J J^T = D^2 (I - u u^T) + t t^T`` with the elbow column
``t = (D - a) p + rho u``, so in the arm plane's basis ``(u, p)``::

    J J^T = [[rho^2, rho (D - a)], [rho (D - a), D^2 + (D - a)^2]]   (+ D^2 along u x p)

the same in every arm plane: its major axis ``v = v_u u + v_p p`` has constant
``(v_u, v_p)``. With ``h`` the unit vector from W to the target, ``h_u = h.u`` and ``beta``
the arm angle of the target itself (:func:`~wholebody.arm.angle.arm_angle`
with the target in place of the elbow)::

    |v.h| = | v_u h_u + v_p |h_perp| cos(alpha - beta) |
    alpha* = beta          if v_u v_p h_u >= 0
             beta + pi     otherwise (wrapped to (-pi, pi])

i.e. the arm plane contains the target, and for a target behind the wrist (``h_u < 0``,
the usual case) the elbow points away from it.

Calibration
-----------
The target position is the model's free parameter. Kim et al. put it at the centre of the
head: :data:`HEAD_CENTRE`, in fractions of stature relative to the shoulder (Drillis &
Contini's proportions as tabulated by Winter, *Biomechanics and Motor Control of Human
Movement*, 4th ed., 2009, Fig. 4.1: shoulder 0.818 H, chin 0.870 H, vertex 1.0 H, shoulder
width 0.259 H). On the bundled seated reaches it predicts an elbow far more lateral than
people hold it (see the data card). :func:`calibrate` therefore fits the target (forward
offset 0, medial and upward offsets on a grid) to minimise the variance of the residual
``alpha_measured - alpha*`` over the well-conditioned frames of the real recordings, then
takes the mean residual as a bias and splits the residual's variance into a per-participant
offset, a per-block offset (one task and arm of one participant), a per-trial offset and a
within-trial Ornstein-Uhlenbeck process (sd and time constant from the lag-0.2 s
autocorrelation). :data:`CALIBRATED` holds the result for the bundled data;
:func:`calibrate` reproduces it.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from wholebody.arm.angle import DOWN, arm_angle
from wholebody.errors import DataError
from wholebody.humanlike.mapping import CANONICAL_SIDE, lab_to_canonical
from wholebody.humanlike.recordings import Participant, Recording

__all__ = [
    "CALIBRATED",
    "HEAD_CENTRE",
    "ArmAngleModel",
    "Calibration",
    "calibrate",
    "elbow_on_circle",
    "kim_arm_angle",
    "summarise_arm_angles",
]

HEAD_CENTRE = (0.0, 0.1295, 0.117)  # forward, medial, up; fractions of stature from the shoulder


def elbow_on_circle(
    S: np.ndarray,
    W: np.ndarray,
    upper_arm: float | np.ndarray,
    forearm: float | np.ndarray,
    alpha: float | np.ndarray,
    side: float,
) -> np.ndarray:
    """The elbow (..., 3) at arm angle ``alpha`` (rad) for shoulder S and wrist W (m, z up).

    ``E = S + a u + rho (cos(alpha) e1 + sin(alpha) e2)`` with ``e1`` the downward reference
    and ``e2 = side (u x g) / |u x g|``, the conventions of
    :func:`~wholebody.arm.angle.arm_angle`, which returns ``alpha`` for it.
    A wrist out of reach (``D > L1 + L2``) puts the elbow on the S-W line.
    """
    S, W = np.asarray(S, dtype=float), np.asarray(W, dtype=float)
    c = W - S
    D = np.linalg.norm(c, axis=-1, keepdims=True)
    u = c / D
    L1 = np.asarray(upper_arm, dtype=float)[..., None]
    L2 = np.asarray(forearm, dtype=float)[..., None]
    a = (L1 * L1 - L2 * L2 + D * D) / (2.0 * D)
    rho = np.sqrt(np.clip(L1 * L1 - a * a, 0.0, None))
    r = DOWN - u * (u @ DOWN)[..., None]
    nr = np.linalg.norm(r, axis=-1, keepdims=True)
    if np.any(nr < 1e-9):
        raise DataError("elbow_on_circle: the shoulder-wrist line is vertical; alpha undefined")
    e1 = r / nr
    e2 = side * np.cross(u, DOWN) / nr
    al = np.asarray(alpha, dtype=float)[..., None]
    return S + a * u + rho * (np.cos(al) * e1 + np.sin(al) * e2)


def kim_arm_angle(
    S: np.ndarray,
    W: np.ndarray,
    upper_arm: float | np.ndarray,
    forearm: float | np.ndarray,
    target: np.ndarray,
    side: float,
    *,
    elbow_down: bool = True,
) -> np.ndarray:
    """Kim et al.'s arm angle (rad, (..., )) for shoulder S, wrist W and head target (m).

    Closed form of the module docstring. Where the target lies on the S-W line the
    criterion does not decide; ``beta`` is then 0 (elbow lowest). With ``elbow_down`` (the
    default, a decision of this project) the candidate with the elbow below the S-W line,
    ``|alpha| <= pi/2``, is taken: it is the criterion's own choice whenever the target is
    behind the wrist (``h_u < 0``, nearly every recorded frame), and otherwise avoids an
    elbow-up posture that no recorded reach shows (a wrist above the head target).
    """
    S, W, target = (np.asarray(v, dtype=float) for v in (S, W, target))
    target = np.broadcast_to(target, np.broadcast_shapes(target.shape, S.shape))
    c = W - S
    D = np.linalg.norm(c, axis=-1)
    u = c / D[..., None]
    L1, L2 = np.asarray(upper_arm, dtype=float), np.asarray(forearm, dtype=float)
    a = (L1 * L1 - L2 * L2 + D * D) / (2.0 * D)
    rho = np.sqrt(np.clip(L1 * L1 - a * a, 0.0, None))
    m_uu, m_up, m_pp = rho * rho, rho * (D - a), D * D + (D - a) ** 2
    lam = 0.5 * (m_uu + m_pp) + np.sqrt(0.25 * (m_pp - m_uu) ** 2 + m_up * m_up)
    v_u, v_p = m_up, lam - m_uu  # major axis, unnormalised (only its signs matter)
    h = target - W
    h_u = np.sum(h * u, axis=-1)
    beta = arm_angle(S, target, W, side)
    flip = v_u * v_p * h_u < 0
    alpha = np.angle(np.exp(1j * np.where(flip, beta + np.pi, beta)))  # wrap to (-pi, pi]
    if elbow_down:
        alpha = np.where(np.abs(alpha) > 0.5 * np.pi, np.angle(np.exp(1j * (alpha + np.pi))), alpha)
    return alpha


@dataclass(frozen=True)
class ArmAngleModel:
    """Kim et al.'s criterion with a target and a noise model (angles in rad, time in s).

    ``alpha = kim_arm_angle(target) + bias + e_participant + e_block + e_trial + e_t``, the
    ``e`` zero-mean normal with the given standard deviations; ``e_t`` an Ornstein-Uhlenbeck
    process of stationary sd ``sd_within`` and time constant ``tau_within``. ``target`` is
    (forward, medial, up) from the shoulder in fractions of stature.
    """

    target: tuple[float, float, float] = HEAD_CENTRE
    bias: float = 0.0
    sd_participant: float = 0.0
    sd_block: float = 0.0
    sd_trial: float = 0.0
    sd_within: float = 0.0
    tau_within: float = 0.5

    def target_point(self, shoulder: np.ndarray, stature: float) -> np.ndarray:
        """The target (m) in canonical axes (x forward, y medial, z up) for a shoulder there."""
        return np.asarray(shoulder, dtype=float) + stature * np.asarray(self.target)

    def predict(
        self, S: np.ndarray, W: np.ndarray, upper_arm: float, forearm: float, stature: float
    ) -> np.ndarray:
        """Noise-free arm angle (rad) of canonical-axes postures (..., 3)."""
        return (
            kim_arm_angle(S, W, upper_arm, forearm, self.target_point(S, stature), CANONICAL_SIDE)
            + self.bias
        )

    def within_trial_noise(self, rng: np.random.Generator, time_s: np.ndarray) -> np.ndarray:
        """One Ornstein-Uhlenbeck path (rad) at the given times (stationary start)."""
        x = np.empty(len(time_s))
        x[0] = rng.normal(0.0, self.sd_within)
        for i in range(1, len(time_s)):
            phi = np.exp(-(time_s[i] - time_s[i - 1]) / self.tau_within)
            x[i] = phi * x[i - 1] + np.sqrt(1.0 - phi * phi) * self.sd_within * rng.normal()
        return x


@dataclass(frozen=True)
class Calibration:
    """The result of :func:`calibrate`: the model and how it compares (degrees)."""

    model: ArmAngleModel
    published_residual: tuple[float, float]  # mean, sd (deg) with HEAD_CENTRE, no bias
    calibrated_residual: tuple[float, float]  # mean, sd (deg) before the bias is removed
    measured: tuple[float, float]  # mean, sd of the measured arm angle (deg)
    frames: int

    def summary(self) -> str:
        m = self.model
        return (
            f"arm-angle model calibration on {self.frames} frames: measured alpha "
            f"{self.measured[0]:.1f} +- {self.measured[1]:.1f} deg; residual with Kim et al.'s "
            f"head-centre target {self.published_residual[0]:.1f} +- "
            f"{self.published_residual[1]:.1f} deg; calibrated target (forward, medial, up) = "
            f"({m.target[0]:.3f}, {m.target[1]:.3f}, {m.target[2]:.3f}) x stature, residual "
            f"{self.calibrated_residual[0]:.1f} +- {self.calibrated_residual[1]:.1f} deg -> "
            f"bias {np.degrees(m.bias):.1f} deg; noise sd participant "
            f"{np.degrees(m.sd_participant):.1f}, block {np.degrees(m.sd_block):.1f}, trial "
            f"{np.degrees(m.sd_trial):.1f}, within-trial {np.degrees(m.sd_within):.1f} deg "
            f"(tau {m.tau_within:.2f} s)"
        )


def _canonical_frames(rec: Recording, every: int):
    sl = slice(None, None, every)
    S = lab_to_canonical(rec.shoulder[sl], rec.side)
    E = lab_to_canonical(rec.elbow[sl], rec.side)
    W = lab_to_canonical(rec.wrist[sl], rec.side)
    return rec.time_s[sl], S, E, W


def calibrate(
    recordings: Sequence[Recording],
    participants: Mapping[str, Participant],
    *,
    every: int = 5,
    medial: np.ndarray | None = None,
    up: np.ndarray | None = None,
    min_elbow_offset: float = 0.04,
    min_tilt: float = np.radians(20.0),
) -> Calibration:
    """Fit :class:`ArmAngleModel` to recorded reaches (module docstring).

    Uses every ``every``-th frame of each recording whose elbow is at least
    ``min_elbow_offset`` (m) from the S-W line and whose S-W line is at least ``min_tilt``
    (rad) from the vertical; the target grid is ``medial`` x ``up`` (fractions of stature).
    """
    medial = np.linspace(-0.05, 0.15, 41) if medial is None else np.asarray(medial)
    up = np.linspace(0.0, 0.30, 61) if up is None else np.asarray(up)
    groups = []
    for rec in recordings:
        if rec.participant not in participants:
            raise DataError(
                f"{rec.path or rec.name}: participant {rec.participant!r} has no "
                "stature in the participants table"
            )
        t, S, E, W = _canonical_frames(rec, every)
        alpha = arm_angle(S, E, W, CANONICAL_SIDE)
        u = (W - S) / np.linalg.norm(W - S, axis=1, keepdims=True)
        a = E - S
        rho = np.linalg.norm(a - np.sum(a * u, axis=1, keepdims=True) * u, axis=1)
        ok = (rho >= min_elbow_offset) & (np.sqrt(1 - u[:, 2] ** 2) >= np.sin(min_tilt))
        if ok.sum() < 3:
            continue
        L1 = float(np.median(rec.upper_arm_lengths()))
        L2 = float(np.median(rec.forearm_lengths()))
        H = participants[rec.participant].stature
        groups.append((rec, t[ok], S[ok], W[ok], alpha[ok], L1, L2, H))
    if not groups:
        raise DataError("calibrate: no well-conditioned frames in the recordings")
    alpha_all = np.concatenate([g[4] for g in groups])
    # flat arrays over all frames, so that each target costs one vectorised evaluation
    S_all = np.concatenate([g[2] for g in groups])
    W_all = np.concatenate([g[3] for g in groups])
    L1_all = np.concatenate([np.full(len(g[1]), g[5]) for g in groups])
    L2_all = np.concatenate([np.full(len(g[1]), g[6]) for g in groups])
    H_all = np.concatenate([np.full(len(g[1]), g[7]) for g in groups])[:, None]
    bounds = np.cumsum([0] + [len(g[1]) for g in groups])

    def flat_residual(target: tuple[float, float, float]) -> np.ndarray:
        T = S_all + H_all * np.asarray(target)
        pred = kim_arm_angle(S_all, W_all, L1_all, L2_all, T, CANONICAL_SIDE)
        return np.angle(np.exp(1j * (alpha_all - pred)))

    def residual(target: tuple[float, float, float]) -> list[np.ndarray]:
        r = flat_residual(target)
        return [r[i:j] for i, j in itertools.pairwise(bounds)]

    pub = flat_residual(HEAD_CENTRE)
    best = None
    for m in medial:
        for h in up:
            var = float(np.var(flat_residual((0.0, float(m), float(h)))))
            if best is None or var < best[0]:
                best = (var, (0.0, float(m), float(h)))
    assert best is not None
    target = best[1]
    res = residual(target)
    flat = np.concatenate(res)
    bias = float(np.mean(flat))
    # variance components: participant > block (task, side) > trial > within trial
    recs = [g[0] for g in groups]
    trial_mean = np.array([np.mean(r) - bias for r in res])
    pids = sorted({r.participant for r in recs})
    pmean = {
        p: np.mean([m for m, r in zip(trial_mean, recs, strict=True) if r.participant == p])
        for p in pids
    }
    blocks: dict[tuple[str, str, str], list[float]] = {}
    for m, r in zip(trial_mean, recs, strict=True):
        blocks.setdefault((r.participant, r.task, r.side), []).append(m - pmean[r.participant])
    bmean = {k: float(np.mean(v)) for k, v in blocks.items()}
    sd_p = float(np.std(list(pmean.values())))
    sd_b = float(np.std(list(bmean.values())))
    sd_t = float(np.sqrt(np.mean([np.var(v) for v in blocks.values()])))
    within = [r - np.mean(r) for r in res]
    sd_w = float(np.std(np.concatenate(within)))
    # lag-0.2 s autocorrelation of the within-trial residual
    num = den = 0.0
    for (_, t, *_rest), w in zip(groups, within, strict=True):
        if len(t) < 3:
            continue
        dt = float(np.median(np.diff(t)))
        lag = max(1, round(0.2 / dt))
        if len(w) > lag:
            num += float(np.sum(w[:-lag] * w[lag:]))
            den += float(np.sum(w * w)) * (len(w) - lag) / len(w)
    corr = min(max(num / den, 1e-3), 0.999) if den > 0 else 0.5
    tau = float(-0.2 / np.log(corr))
    model = ArmAngleModel(target, bias, sd_p, sd_b, sd_t, sd_w, tau)
    deg = np.degrees
    return Calibration(
        model,
        (float(deg(np.mean(pub))), float(deg(np.std(pub)))),
        (float(deg(np.mean(flat))), float(deg(np.std(flat)))),
        (float(deg(np.mean(alpha_all))), float(deg(np.std(alpha_all)))),
        len(flat),
    )


# The participants CALIBRATED is fitted on: the bundled real ones except those the stiffness
# network holds out for its scores (wholebody.humanlike.dataset.DEFAULT_TEST_PARTICIPANTS),
# so that no held-out participant shapes the synthetic training data.
CALIBRATED_ON = (
    "ADL001",
    "ADL002",
    "ADL004",
    "ADL005",
    "ADL006",
    "ADL007",
    "ADL009",
    "ADL010",
    "ADL012",
)

# The result of calibrate() on the recordings of CALIBRATED_ON (every 5th well-conditioned
# frame: 12798 frames): measured alpha 5.8 +- 11.6 deg; residual with the head-centre target
# -44.3 +- 12.2 deg, with the calibrated target -12.6 +- 11.0 deg. `wholebody stiffness
# dataset --calibrate` re-runs it.
CALIBRATED = ArmAngleModel(
    target=(0.0, 0.010, 0.035),
    bias=-0.22014,
    sd_participant=0.09817,
    sd_block=0.10398,
    sd_trial=0.04258,
    sd_within=0.12286,
    tau_within=1.392,
)


def with_target(model: ArmAngleModel, target: tuple[float, float, float]) -> ArmAngleModel:
    """A copy of ``model`` with another target (fractions of stature)."""
    return replace(model, target=target)


def summarise_arm_angles(recordings: Sequence[Recording]) -> dict[str, float]:
    """Arm-angle statistics (deg) of recordings: mean and sd at the first and last frame,
    over all frames, and the fraction of frames with alpha < 0."""
    if not recordings:
        raise DataError("summarise_arm_angles: no recordings")
    per = [np.degrees(arm_angle(r.shoulder, r.elbow, r.wrist, r.side_sign)) for r in recordings]
    start = np.array([a[0] for a in per])
    end = np.array([a[-1] for a in per])
    every = np.concatenate(per)
    return {
        "trials": len(per),
        "frames": int(every.size),
        "start_mean": float(start.mean()),
        "start_sd": float(start.std()),
        "end_mean": float(end.mean()),
        "end_sd": float(end.std()),
        "all_mean": float(every.mean()),
        "all_sd": float(every.std()),
        "negative_fraction": float(np.mean(every < 0)),
    }
