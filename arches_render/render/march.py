"""What every field tracer shares: the over-relaxed sphere step, its loop state and its result.

For a field ``f`` (positive inside) whose ``eval_bounds`` returns, at a point ``p`` of a
ray, a free radius ``r`` along the ray's line (no point of ``{f >= 0}`` within ``|s| < r``
of ``p`` on that line; a free ball is one such bound), a ray may advance by ``r``
(Hart 1996). Over-relaxation (Keinert et al. 2014) advances by ``omega r`` instead;
the step from ``t_prev`` to ``t`` was safe when the free intervals of the two points
overlap,

    r_prev + r >= t - t_prev,

since then ``[t_prev, t]`` is covered by them. Otherwise the march returns to the
last verified point ``t_prev + r_prev``, takes the plain step and relaxes again
after it (a failed step costs one plain step, not the relaxation of the rest of
the ray). At every moment ``[t_start, t_prev + r_prev]`` is proven free: that is the
*verified frontier* a ray reports when its budget runs out.

The test reads ``r_prev`` only ahead of ``t_prev`` and ``r`` only behind ``t``. So a
point that no relaxed step led to (a ray's start, the frontier after a failed step,
a plain step) may be answered with a length free ahead only (``field.node``,
"Ahead"), which the tracers ask for there: a shadow ray leaving the ground, whose
two-sided length is ~0, then takes its first step to the end of what the ground's
slope along it allows (fig23_coastal_cliff, 320x180: shadow 21.2 -> 15.5, bounce
22.7 -> 18.7 steps a ray).

A step stops on the surface when ``-f < tol`` (a tolerance that grows with distance,
chosen by the tracer) or when ``f >= 0`` (a ray that starts exactly on or inside the
surface, where ``tol`` may be 0, would otherwise take zero-length steps forever), never
on ``-f / L < tol``: a loose ``L`` would stop rays early and inflate thin features.
A NaN ``f`` or ``r`` proves nothing: the step reports the lane *invalid*, and
the tracer resolves it conservatively (an unresolved hit at its verified frontier),
never as a miss: ``min(t + omega r, t_end)`` with a NaN ``r`` would otherwise jump to
the end of the ray.

Adaptive relaxation. A fixed ``omega`` fails where the bound is within a few times
the true slope: approaching a wall, ``r`` falls by ``beta = -g / K`` per unit of ``t``
(``g`` the directional derivative, ``K`` the bound's slope), and a step ``omega r``
overlaps the next free interval only if ``omega <= 2 / (1 - beta)``; with ``omega = 1.6``
every second step failed wherever ``g / K > 1/4`` (a Jacksboro channel wall: ``g / K =
0.47``, 35 evaluations where plain steps need 18). So the step leaving a verified
point takes ``omega = 0.9 * 2 / (1 - beta)`` in ``[1, omega0]``, ``beta`` measured between
the last two verified points (Bálint and Valasek 2018 predict the step from the same
planar model). It changes only where the ray goes next: the overlap test still
decides what is verified (camera steps, 320x180: Jacksboro 42.0 -> 36.6, NM canyon
34.2 -> 29.7, goblins 53.1 -> 49.0, every_generator 27.2 -> 24.8).

Steps stop at ``t_end``, so that a relaxed step past the end is still checked there
before the ray may leave (else it could skip a surface just before a mesh).

Shadow probes. A shadow ray needs *a* hit, not the first: any point of its segment
within the hit tolerance of the solid (or inside it) proves it blocked, whether or not
the steps that led there were verified. A ray closing on a wall that its bound
overestimates ``K / g``-fold only shrinks its distance by about ``omega g / K`` a step
(``g`` the directional derivative), so it took hundreds of steps to creep up to a wall it
was bound to hit (goblins: blocked shadow rays 60.6 steps, 381 at the 99th percentile,
against 49.6 for free ones). So a shadow ray whose value rises between its last
verified point and the next point takes, instead of the relaxed step, the secant's zero
``t + (-f) (t - t_prev) / (f - f_prev)`` pushed ``PROBE_BEYOND`` past it when that is
farther: a probe. A probe that lands in the rock (or within the tolerance) is the hit;
one that lands in air is checked by the overlap test as a relaxed step is (its value
is kept only where the free intervals cover the jump), and a failed one costs one plain
step. After ``PROBE_FAILURES`` failures (a ray grazing a wall, whose value rises then
falls) a ray probes again only after ``PROBE_BACKOFF`` accepted steps without one, a
span that doubles with every further failure: a ray that grazed one wall and then closes
on another no longer creeps up to it without probes (a floating island's shadow ray:
250 steps from 0.08 to 0.31 m, its value halving every 26), and a ray that keeps
grazing pays one failed probe per ``PROBE_BACKOFF``, 2 ``PROBE_BACKOFF``, ... steps.

References
----------
Hart, J. C. (1996). Sphere tracing. The Visual Computer 12(10).
Keinert, B., Schäfer, H., Korndörfer, J., Ganse, U., Stamminger, M. (2014). Enhanced
sphere tracing. STAG 2014, 1-8.
Bálint, C., Valasek, G. (2018). Accelerating sphere tracing. Eurographics 2018 short
papers, 29-32.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi

__all__ = ["SECOND_PASS_FACTOR", "March", "ShadowProbe", "StepOutcome", "TraceResult", "adaptive_relaxation",
           "march_result", "position_ulps", "ray_box", "relaxed_step", "secant_probe"]

#: A ray that exhausts ``max_steps`` goes on for this many times more steps.
SECOND_PASS_FACTOR = 16


@dataclass
class TraceResult:
    """What a ray query found, per lane.

    Attributes
    ----------
    hit : mi.Bool
        A surface was met (unresolved rays included: they are conservative hits).
    t : mi.Float
        Distance of the hit (for unresolved rays, of their verified frontier).
    steps : mi.UInt32
        Field evaluations the ray took (sphere steps); the step budgets count these.
    exhausted : mi.Bool
        The ray used up its first budget (``max_steps``).
    unresolved : mi.Bool
        The ray used up the second budget too, or met a value that proves nothing
        (NaN), or a traversal's iteration guard; it was resolved as a hit.
    cells : mi.UInt32
        Cheap iterations besides the steps: cells a structure or a heightfield cast
        visited without evaluating the field (0 for a plain sphere tracer).
    """

    hit: object
    t: object
    steps: object
    exhausted: object
    unresolved: object
    cells: object = None

    @classmethod
    def of(cls, hit, t, steps, unresolved, active, max_steps, cells=None):
        """The result of a loop that ended with ``unresolved`` lanes (still alive at its
        end, or stopped without proof)."""
        unresolved = mi.Bool(unresolved) & active
        return cls(hit=(mi.Bool(hit) | unresolved) & active, t=t, steps=mi.UInt32(steps),
                   exhausted=active & (steps > max_steps) | unresolved, unresolved=unresolved,
                   cells=mi.UInt32(0) if cells is None else mi.UInt32(cells))


def march_result(march, hit, alive, invalid, steps, active, max_steps, cells=None):
    """The :class:`TraceResult` of a sphere march that ended with ``alive`` lanes still
    going (their budget ran out) and ``invalid`` ones stopped by a NaN: both are
    unresolved, reported at their verified frontier, never at a relaxed point that
    may lie past a thin wall."""
    unresolved = alive | invalid
    t = dr.select(unresolved, dr.minimum(march.t, march.frontier), march.t)
    return TraceResult.of(hit, t, steps, unresolved, active, max_steps, cells=cells)


def position_ulps(p, ulps):
    """``ulps`` float32 units in the last place of the largest coordinate of ``p`` (plus 1e-6 m).

    Rounding of a position, and of a field value computed from it, is a few ulps of
    its largest coordinate: gradient taps (64 ulps: 1e-3 relative error) and ray
    offsets (32: well above the noise of ``f``) scale with it, not with the scene's
    size (issue 14: a fixed fraction of a 1000 km tile is metres, far coarser than a
    close shot needs near the origin).
    """
    m = dr.maximum(dr.maximum(dr.abs(p.x), dr.abs(p.y)), dr.abs(p.z))
    return ulps * 1.1920929e-7 * m + 1e-6


def ray_box(o, d, lo, hi):
    """Slab test: entry and exit distances of the ray ``o + t d`` through ``[lo, hi]``
    (``lo``, ``hi``: three floats or three ``mi.Float``)."""
    inv = dr.rcp(d)
    t0 = (mi.Vector3f(*lo) - o) * inv
    t1 = (mi.Vector3f(*hi) - o) * inv
    tn = dr.minimum(t0, t1)
    tf = dr.maximum(t0, t1)
    return dr.max(tn), dr.min(tf)


@dataclass
class March:
    """The loop state of an over-relaxed sphere march, per lane (module docstring).

    Attributes
    ----------
    t : mi.Float
        Where the field is evaluated next (a relaxed point: not yet verified).
    t_prev : mi.Float
        The last point whose free radius ``r_prev`` was accepted.
    r_prev : mi.Float
        Its free length ahead along the ray; ``t_prev + r_prev`` is the verified frontier.
    step : mi.Float
        ``t - t_prev``, what the overlap test must cover.
    omega : mi.Float
        The relaxation of the step that led to ``t`` (1 after a failed step, when the
        next evaluation is at the verified frontier).
    """

    t: object = field(default_factory=lambda: mi.Float())
    t_prev: object = field(default_factory=lambda: mi.Float())
    r_prev: object = field(default_factory=lambda: mi.Float())
    step: object = field(default_factory=lambda: mi.Float())
    omega: object = field(default_factory=lambda: mi.Float())

    @classmethod
    def start(cls, t, omega):
        """A march about to evaluate the field at ``t`` (nothing to verify yet)."""
        # Dr.Jit traverses loop state through DRJIT_STRUCT; its types belong to the
        # variant chosen at run time, so it is declared here, not at import.
        cls.DRJIT_STRUCT = {name: mi.Float for name in ("t", "t_prev", "r_prev", "step", "omega")}
        t = mi.Float(t)
        return cls(t=mi.Float(t), t_prev=mi.Float(t), r_prev=dr.zeros(mi.Float, dr.width(t)),
                   step=dr.zeros(mi.Float, dr.width(t)), omega=mi.Float(omega) + dr.zeros(mi.Float, dr.width(t)))

    @property
    def frontier(self):
        """``t_prev + r_prev``: the ray is proven free up to here."""
        return self.t_prev + self.r_prev


@dataclass
class StepOutcome:
    """What one :func:`relaxed_step` decided, per lane.

    Attributes
    ----------
    hit : mi.Bool
        The surface is at ``march.t`` (within the tolerance, or the point is inside).
    done : mi.Bool
        ``[t_start, t_end]`` is proven free: the ray leaves.
    invalid : mi.Bool
        The field returned a value that proves nothing (NaN): the lane
        must be resolved conservatively.
    failed : mi.Bool
        The relaxed step that led to ``march.t`` overshot: the march went back to
        its verified frontier.
    probed : mi.Bool
        The next point is a shadow probe (:func:`secant_probe`).
    """

    hit: object
    done: object
    invalid: object
    failed: object
    probed: object = False


#: The fraction of the predicted overlap limit ``2 r / (1 - beta)`` a relaxed step takes
#: (module docstring): 1 touches it exactly and fails on every convex wall; of 0.8, 0.85,
#: 0.9, 0.95 and 1 on Jacksboro, NM canyon, goblins and every_generator, 0.85-0.95 had
#: the fewest camera steps (Jacksboro 36.4 a ray at 0.9 against 37.7 at 0.8 and 40.8 at 1,
#: measured with a carving bound since dropped, worth 0.2 of a step there).
RELAX_MARGIN = 0.9


def adaptive_relaxation(march, r, omega0):
    """The relaxation of the step that leaves ``march.t`` (module docstring, "Adaptive
    relaxation"): ``RELAX_MARGIN 2 / (1 - beta)`` in ``[1, omega0]``, ``beta`` the change
    of the free radius per unit of ``t`` since the last verified point; ``omega0`` on a
    march's first step and where the radius does not shrink."""
    m = march
    beta = (r - m.r_prev) * dr.rcp(m.step)
    predicted = dr.clip(RELAX_MARGIN * 2.0 * dr.rcp(1.0 - beta), 1.0, omega0)
    return dr.select((m.step <= 0.0) | (beta >= 0.0), omega0, predicted)


def relaxed_step(march, f, r, t_end, tol, omega0, probe=None):
    """One over-relaxed sphere step from the field's answer at ``march.t`` (module docstring).

    Parameters
    ----------
    march : March
        The state before the step (not modified).
    f, r : mi.Float
        The field's value and free radius along the ray at ``march.t``.
    t_end : mi.Float
        The end of the ray's interval.
    tol : mi.Float
        The hit tolerance at ``march.t``.
    omega0 : float or mi.Float
        The largest relaxation (:func:`adaptive_relaxation` chooses the step's).
    probe : mi.Float, optional
        A shadow ray's probe (:func:`secant_probe`; 0: none): the next point where it is
        farther than the relaxed step. With it, a hit anywhere counts (module
        docstring, "Shadow probes"); without it, only at a point the overlap test verified.

    Returns
    -------
    (March, StepOutcome)
        The state after the step (unchanged where the step hit or was invalid) and
        its outcome.
    """
    m = march
    # (An infinite free radius is a proof: the whole line is free.)
    invalid = dr.isnan(f) | dr.isnan(r)
    failed = ~invalid & (m.omega > 1.0) & (r + m.r_prev < m.step)
    hit = ~invalid & ((-f < tol) | (f >= 0.0))
    if probe is None:
        hit &= ~failed
    failed &= ~hit
    w = adaptive_relaxation(m, r, omega0)
    # Relaxed step overshot: return to the verified frontier (the plain step from t_prev).
    t_next = dr.select(failed, m.frontier, dr.minimum(m.t + w * r, t_end))
    probed = mi.Bool(False)
    if probe is not None:
        probed = ~failed & (probe > t_next)
        t_next = dr.select(probed, probe, t_next)
        # A probe is checked as a relaxed step is (omega > 1: the overlap test applies).
        w = dr.select(probed, dr.maximum(w, 2.0), w)
    done = ~failed & ~hit & ~invalid & (m.t >= t_end)
    stay = hit | invalid
    out = March(t=dr.select(stay, m.t, t_next),
                t_prev=dr.select(failed | stay, m.t_prev, m.t),
                r_prev=dr.select(failed | stay, m.r_prev, r),
                # After a failure the next evaluation is at the frontier: step = r_prev
                # makes the overlap test there trivially satisfied.
                step=dr.select(stay, m.step, dr.select(failed, m.r_prev, t_next - m.t)),
                omega=dr.select(stay, m.omega, dr.select(failed, 1.0, w)))
    return out, StepOutcome(hit=hit, done=done, invalid=invalid, failed=failed, probed=probed & ~stay)


#: How far past the secant's zero a shadow probe lands, as a multiple of the distance to
#: it (module docstring, "Shadow probes"): past it, so that a wall the secant predicts
#: well is entered, not approached (1.1, 1.25, 1.5 and 2 were within 1.5 steps of each
#: other; 1.25 the fewest).
PROBE_BEYOND = 1.25

#: Failed probes after which a shadow ray marches without them. Shadow steps (mean, and
#: 99th percentile of blocked rays) on goblins / every_generator / arch bridge at 320x180,
#: probing 1.25 past the secant's zero: 2 failures 45.8, 184 / 22.4, 119 / 31.8, 292; 4:
#: 44.9, 162 / 22.3, 121 / 30.7, 253; 8: free rays pay more (goblins 50.8 -> 51.6) than
#: blocked ones gain. (Without probes: 53.5, 381 / 23.2, 118 / 35.3, 361.) Capping a
#: probe at 16 free radii ahead kept half of the gain away: the probes that pay jump far.
PROBE_FAILURES = 4

#: Accepted steps after which a ray past ``PROBE_FAILURES`` failures probes again,
#: doubled with each failure after those (module docstring, "Shadow probes"); 0: never
#: again. Shadow steps (mean, p99) at 320x180, none -> 16: floating islands 26.4, 195 ->
#: 24.5, 149; arch bridge 23.1, 141 -> 22.6, 128; goblins 38.9, 142 -> 38.3, 137
#: (4 and 8 within 0.3 steps of 16).
PROBE_BACKOFF = 16


@dataclass
class ShadowProbe:
    """A shadow ray's probe state (module docstring, "Shadow probes").

    Attributes
    ----------
    f_prev : mi.Float
        The field's value at the march's last verified point ``t_prev``.
    probing : mi.Bool
        The march's next point was reached by a probe.
    failures : mi.UInt32
        Probes that failed the overlap test so far.
    quiet : mi.UInt32
        Accepted steps since the last failed probe.
    """

    f_prev: object = field(default_factory=lambda: mi.Float())
    probing: object = field(default_factory=lambda: mi.Bool())
    failures: object = field(default_factory=lambda: mi.UInt32())
    quiet: object = field(default_factory=lambda: mi.UInt32())

    @classmethod
    def start(cls, width):
        """No verified point yet (``march.step`` is 0 there, so no probe is taken)."""
        cls.DRJIT_STRUCT = {"f_prev": mi.Float, "probing": mi.Bool, "failures": mi.UInt32, "quiet": mi.UInt32}
        return cls(f_prev=dr.zeros(mi.Float, width), probing=dr.zeros(mi.Bool, width),
                   failures=dr.zeros(mi.UInt32, width), quiet=dr.zeros(mi.UInt32, width))

    def allowed(self):
        """Whether the ray may probe now: fewer than ``PROBE_FAILURES`` failures, or
        ``PROBE_BACKOFF 2^(failures - PROBE_FAILURES)`` accepted steps since the last."""
        first = self.failures < PROBE_FAILURES
        if not PROBE_BACKOFF:
            return first
        extra = dr.minimum(self.failures, PROBE_FAILURES + 16) - PROBE_FAILURES
        return first | (self.quiet >= (mi.UInt32(PROBE_BACKOFF) << extra))

    def after(self, outcome, f):
        """The state after a step that evaluated ``f`` at the march's point and ended in
        ``outcome``: the point becomes the verified one unless the step failed or stopped."""
        accepted = ~(outcome.failed | outcome.hit | outcome.invalid)
        lost = self.probing & outcome.failed
        return ShadowProbe(f_prev=dr.select(accepted, f, self.f_prev), probing=outcome.probed,
                           failures=self.failures + dr.select(lost, 1, 0),
                           quiet=dr.select(lost, 0, self.quiet + dr.select(accepted, 1, 0)))


def secant_probe(march, f, probe, t_end):
    """Where a shadow ray probes next (module docstring, "Shadow probes"), or 0.

    Parameters
    ----------
    march : March
        The state at the point just evaluated.
    f : mi.Float
        The field's value there.
    probe : ShadowProbe
        The ray's probe state (``f_prev`` at ``march.t_prev``).
    t_end : mi.Float
        The end of the ray's interval.

    Returns
    -------
    mi.Float
        ``t + PROBE_BEYOND (-f) (t - t_prev) / (f - f_prev)`` (at most ``t_end``) where the value
        rose from a verified point and the ray may probe (:meth:`ShadowProbe.allowed`); 0 elsewhere.
    """
    m = march
    closing = (m.step > 0.0) & (f > probe.f_prev) & (f < 0.0) & probe.allowed()
    reach = PROBE_BEYOND * (-f) * (m.t - m.t_prev) * dr.rcp(dr.maximum(f - probe.f_prev, 1e-30))
    return dr.select(closing, dr.minimum(m.t + reach, t_end), 0.0)
