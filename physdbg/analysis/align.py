"""Where two runs part: aligning frames, comparing states, measuring how a gap grows.

Used by ``physdbg diff`` and by ``replay --verify`` (a re-simulation against its file),
so there is one way to find and describe a divergence.

Alignment. When both runs took the same steps (every dt equal), frame k of one is
compared with frame k of the other, and the stored state hashes find the first frame
that differs without decoding a state. Otherwise frames are aligned by simulated time:
each frame of the run with the longer steps is compared with the other run at the same
time — its frame there when one exists (within 1e-9 of a step), else a cubic Hermite
interpolation between the two frames around it (positions from positions and
velocities, velocities linearly). Interpolation is exact for free flight under constant
acceleration, and only approximate across a contact inside the interval.
"""

from __future__ import annotations


from dataclasses import asdict, dataclass, field

import numpy as np

from ..engine.periodic import minimum_image, unwrap_near


@dataclass
class StateDifference:
    """How two states differ. particles: the most different first (at most 5), each
    {"particle", "position", "velocity"} with |Δx| (m) and |Δv| (m/s); count: how many
    particles differ beyond the tolerance; max_position, max_velocity: over all."""

    count: int
    max_position: float
    max_velocity: float
    particles: list[dict] = field(default_factory=list)

    def as_dict(self) -> dict:
        return asdict(self)


def state_difference(xa, va, xb, vb, atol: float = 0.0, rtol: float = 0.0, period=None) -> StateDifference:
    """Compare two states (N, 3) each; with atol = rtol = 0 any bit of difference counts.
    period: (3,) m of a periodic box (0 = not periodic; None = none), whose positions
    differ through the minimum image (a sphere wrapped in one run only is near)."""
    dx = np.linalg.norm(position_gap(xa, xb, period), axis=1)
    dv = np.linalg.norm(va - vb, axis=1)
    if atol == 0.0 and rtol == 0.0:
        beyond = np.any(xa != xb, axis=1) | np.any(va != vb, axis=1)
        beyond |= np.isnan(dx) | np.isnan(dv)
    else:
        beyond = (dx > atol + rtol * np.linalg.norm(xb, axis=1)) | (dv > atol + rtol * np.linalg.norm(vb, axis=1))
        beyond |= ~np.isfinite(dx) | ~np.isfinite(dv)
    order = np.argsort(-(np.nan_to_num(dx, nan=np.inf) + np.nan_to_num(dv, nan=np.inf)), kind="stable")
    top = [int(i) for i in order[:5] if beyond[i]]
    return StateDifference(int(beyond.sum()), float(np.nanmax(dx)) if len(dx) else 0.0,
                           float(np.nanmax(dv)) if len(dv) else 0.0,
                           [{"particle": i, "position": float(dx[i]), "velocity": float(dv[i])} for i in top])


def first_differing_frame(hashes_a: np.ndarray, hashes_b: np.ndarray) -> int | None:
    """First frame whose stored hashes differ among the frames both have ((F, 16) uint8)."""
    n = min(len(hashes_a), len(hashes_b))
    differ = np.nonzero(np.any(hashes_a[:n] != hashes_b[:n], axis=1))[0]
    return int(differ[0]) if len(differ) else None


def same_steps(dt_a: np.ndarray, dt_b: np.ndarray) -> bool:
    """Did both runs take the same steps (bit-equal dt) for the frames both have?"""
    n = min(len(dt_a), len(dt_b))
    return bool(np.array_equal(dt_a[:n], dt_b[:n]))


def position_gap(xa, xb, period=None):
    """xa - xb (N, 3), through the minimum image on the periodic axes of period (3,) m."""
    return xa - xb if period is None else minimum_image(xa - xb, period)


def hermite(t: float, a, b, period=None):
    """State (x (N, 3), v (N, 3)) at time t between two FrameStates a (earlier) and b
    (in a periodic box of period (3,) m, b's positions taken next to a's: a sphere that
    wrapped between the frames is interpolated along its path, not across the box)."""
    h = b.time - a.time
    if h <= 0.0:
        return a.positions, a.velocities
    s = (t - a.time) / h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    xb = b.positions if period is None else unwrap_near(b.positions, a.positions, period)
    x = h00 * a.positions + h10 * h * a.velocities + h01 * xb + h11 * h * b.velocities
    v = (1 - s) * a.velocities + s * b.velocities
    return x, v


# A gap is called chaotic only when the two runs show a finite-time Lyapunov exponent: the
# gap (below one radius, before it saturates) grows at one exponential rate over at least
# this many e-folds, fits that rate this well, and spheres collide while it does (flat walls
# alone amplify no difference: a ball bouncing on a floor, or coasting, drifts, it is not chaos)
LYAPUNOV_MIN_EFOLDS = 3.0
LYAPUNOV_MIN_R2 = 0.75  # log gap rises in jumps at collisions: a chaotic gas fits ~0.85
STEADY_EXPONENT = 0.05
POOR_FIT_R2 = 0.5  # below this, neither model describes the gap: say so rather than quote a rate  # a power-law exponent this close to 0 is a gap that stays the same size


@dataclass
class Growth:
    """How the gap (largest |Δx| over particles, m) grows after the divergence.

    steps_to_mm / steps_to_radius: steps after the first differing one until the gap
    reaches 1 mm / the smallest radius (None: never within the runs); model:
    "exponential" (gap ~ e^(rate·t), rate in 1/s), "power" (gap ~ t^rate), "steady" (the
    same size throughout) or "" when there are too few points; fit_r2: how well (in log
    gap); efolds: rate × the span fitted (exponential); chaotic: the exponential rate is a
    finite-time Lyapunov exponent (see LYAPUNOV_MIN_EFOLDS), not_chaotic: why not, when the
    exponential fits best; samples: (step, gap) pairs measured."""

    steps_to_mm: int | None
    steps_to_radius: int | None
    radius: float
    model: str
    rate: float
    fit_r2: float
    final_gap: float
    samples: list[tuple[int, float]]
    efolds: float = 0.0
    chaotic: bool = False
    not_chaotic: str = ""

    def as_dict(self) -> dict:
        out = asdict(self)
        out["samples"] = [list(s) for s in self.samples]
        return out

    def judge_chaos(self, spheres_collide: bool) -> None:
        """Call the growth chaotic when its exponential rate is a finite-time Lyapunov
        exponent: steady over LYAPUNOV_MIN_EFOLDS e-folds, a good fit, and spheres that
        collide (the mechanism that amplifies a difference)."""
        self.chaotic = False
        if self.model != "exponential" or not self.rate > 0:
            self.not_chaotic = ""
            return
        if not spheres_collide:
            self.not_chaotic = "no two spheres collide, and flat walls amplify no difference"
        elif self.efolds < LYAPUNOV_MIN_EFOLDS:
            self.not_chaotic = f"only {self.efolds:.1f} e-folds before it saturates, too few to tell chaos from drift"
        elif self.fit_r2 < LYAPUNOV_MIN_R2:
            self.not_chaotic = f"the exponential fits it poorly (R² = {self.fit_r2:.2f})"
        else:
            self.chaotic, self.not_chaotic = True, ""

    def sentence(self) -> str:
        parts = []
        broken = next((step for step, gap in self.samples if not np.isfinite(gap)), None)
        if broken is not None:
            return (f"the gap cannot be measured from step {broken} on: a position there is NaN or infinite in one "
                    f"run")
        if self.steps_to_mm == 0 and self.samples:
            parts.append(f"is already {self.samples[0][1]:.3g} m in that step and {self.final_gap:.3g} m at the end")
        elif self.steps_to_mm is not None:
            parts.append(f"reaches 1 mm after {_steps(self.steps_to_mm)}")
        if self.steps_to_radius == 0:
            parts.append(f"more than one radius ({self.radius:.3g} m) from the first")
        elif self.steps_to_radius is not None:
            parts.append(f"one radius ({self.radius:.3g} m) after {_steps(self.steps_to_radius)}")
        if not parts:
            parts.append(f"stays below 1 mm (at most {self.final_gap:.3g} m at the end)")
        if self.model in ("exponential", "power") and self.fit_r2 < POOR_FIT_R2:
            parts.append(f"it rises and falls with no steady trend (no power of time or exponential fits it: "
                         f"R² = {self.fit_r2:.2f})")
        elif self.model == "exponential" and self.rate > 0:
            if self.chaotic:
                parts.append(f"it grows exponentially, ×e every {1 / self.rate:.3g} s over {self.efolds:.1f} e-folds "
                             f"(a finite-time Lyapunov exponent of {self.rate:.3g} 1/s: chaotic, collisions amplify "
                             f"any difference)")
            else:
                parts.append(f"it grows about ×e every {1 / self.rate:.3g} s (not chaos: {self.not_chaotic})")
        elif self.model == "power":
            parts.append(f"it grows like t^{self.rate:.2f} (a smooth drift)" if self.rate > STEADY_EXPONENT else
                         f"it shrinks like t^{self.rate:.2f}" if self.rate < -STEADY_EXPONENT else
                         "it stays about the same size")
        elif self.model == "steady":
            parts.append("it stays the same size")
        return "the gap " + ", ".join(parts)


def _steps(n: int) -> str:
    return f"{n} more step{'' if n == 1 else 's'}"


def fit_growth(steps: np.ndarray, times: np.ndarray, gaps: np.ndarray, radius: float, first_step: int,
               first_time: float, dt: float) -> Growth:
    """Growth of (steps, times, gaps) samples after a divergence at ``first_step`` (its
    frame at ``first_time`` s, reached by a step of ``dt`` s; 0 when the runs differ from
    frame 0, where a typical step is used). Total: any samples (none, one, constant, NaN,
    infinite) give a Growth, never a warning or an error."""
    order = np.argsort(steps)
    steps, times, gaps = steps[order], times[order], gaps[order]

    def first_reaching(level: float) -> int | None:
        at = np.nonzero(gaps >= level)[0]
        return int(steps[at[0]] - first_step) if len(at) else None

    if not dt > 0:  # the runs differ from frame 0: time counts from one typical step before it
        spacing = np.diff(times)
        spacing = spacing[np.isfinite(spacing) & (spacing > 0)]
        dt = float(np.median(spacing)) if len(spacing) else 1.0
    elapsed_all = times - first_time + dt
    use = (gaps > 0) & np.isfinite(gaps) & (gaps < radius) & np.isfinite(elapsed_all) & (elapsed_all > 0)
    model, rate, r2, efolds = "", 0.0, 0.0, 0.0
    if use.sum() >= 3:
        with np.errstate(all="ignore"):
            y = np.log(gaps[use])
            elapsed = elapsed_all[use]
            if np.ptp(y) == 0:
                model, r2 = "steady", 1.0
            else:
                best = None
                for name, x in (("exponential", elapsed), ("power", np.log(elapsed))):
                    if not np.ptp(x) > 0:
                        continue
                    try:
                        slope, intercept = np.polyfit(x, y, 1)
                    except (np.linalg.LinAlgError, ValueError):
                        continue
                    residual = y - (slope * x + intercept)
                    total = float(np.sum((y - y.mean()) ** 2))
                    score = 1 - float(np.sum(residual**2)) / total if total > 0 else 1.0
                    if np.isfinite(slope) and np.isfinite(score) and (best is None or score > best[2] + 1e-9):
                        best = (name, float(slope), float(score))
                if best is not None:
                    model, rate, r2 = best
                    if model == "exponential":
                        efolds = rate * float(np.ptp(elapsed))
    samples = [(int(s), float(g)) for s, g in zip(steps, gaps, strict=True)]
    return Growth(first_reaching(1e-3), first_reaching(radius), radius, model, rate, r2,
                  float(gaps[-1]) if len(gaps) else 0.0, samples[:400], efolds)


__all__ = ["Growth", "StateDifference", "first_differing_frame", "fit_growth", "hermite",
           "same_steps", "state_difference"]

