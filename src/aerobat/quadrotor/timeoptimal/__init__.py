"""Time-optimal hover-to-hover motions of a planar quadrocopter.

This package reproduces the time-optimal benchmark of Ritz et al. (2011) and
Hehn, Ritz & D'Andrea (2012): a mass-normalised vehicle in the vertical
plane with state ``(y, z, vy, vz, theta)`` and dynamics

.. math::

    \\ddot y = f \\sin\\theta, \\qquad \\ddot z = f \\cos\\theta - g,
    \\qquad \\dot\\theta = \\omega,

with collective thrust ``f in [f_min, f_max]`` and body rate
``|omega| <= omega_max``, starts in hover at the origin and must reach hover
at ``(Y, Z)`` with attitude ``final_angle_rad`` in minimum time.

The solution proceeds in three stages, one module each (``transcription``,
``structure`` + ``refinement``, ``optimality`` + ``repair``; ``solve`` runs them):

1. **Structure.**  A direct transcription (piecewise-constant inputs, one
   classical Runge-Kutta step per interval, free final time) is solved with
   CasADi/IPOPT.  Coarse (30-interval) multi-starts with different attitude
   guesses select the basin of the best local optimum (for vertical moves
   ``theta == 0`` is only a stationary point; tilting/flipping is faster),
   which is then re-solved on the requested grid.
2. **Refinement.**  The arc structure of both inputs is read off the
   transcription (thrust: bang-bang; rate: bang-singular) and the arc
   durations are optimised directly (switching-time optimisation, IPOPT,
   tolerance 1e-13).  Pieces on which both inputs are constant are
   integrated in closed form.  On a singular rate arc Pontryagin's principle
   gives ``lambda_theta = 0`` and hence ``tan(theta) = lambda_vy / lambda_vz``
   with ``lambda_v`` affine in time: the attitude follows a *bilinear
   tangent law* along one costate line ``n(t) = (a + b t, c + d t)`` shared
   by all singular arcs.  Per arc this reads

   .. math::

       \\theta(t_a + s) = \\theta(t_a) + \\operatorname{atan2}(\\beta s, 1 + \\alpha s),

   whose rate ``beta / ((1 + alpha s)^2 + (beta s)^2)`` is in general *not*
   constant (it is below 0.03 rad/s for the (5, 5) benchmark but varies
   between -0.3 and -4 rad/s for the (5, 0) move).  The line ``(a, b, c, d)``
   is therefore a decision variable (initialised from the transcription's
   multipliers, i.e. its discrete adjoint); the translational integrals of
   singular pieces use composite Gauss-Legendre quadrature (4 x 32 nodes).
3. **Certification and repair.**  The multipliers of the final-state
   constraints are the adjoint ``lambda(T)``; propagating it backwards gives
   the switching functions, and the minimum principle is checked on every
   arc (thrust sign, rate sign, ``lambda_theta = 0`` on singular arcs).  If
   it is violated, the refinement is restarted from the multipliers' costate
   line and/or the arc that the needle variation asks for is inserted (a
   bang arc, or a short singular arc between opposite rate bangs) and the
   refinement repeated.

A result is ``'optimal'`` only if IPOPT converged, the refined program,
re-integrated independently with an adaptive high-order ODE solver, meets
the boundary conditions to 1e-6, the inputs respect their bounds, the
refined time does not exceed the transcription's and the minimum principle
holds to 1e-6 (typically 1e-12).  Otherwise a solution with
``status == 'failed'`` and an explanatory message is returned instead of a
plausible-looking wrong answer.
"""

from aerobat.quadrotor.timeoptimal.solution import ArcKind, BenchmarkLimits, InputArc, SolveStatus, TimeOptimalSolution
from aerobat.quadrotor.timeoptimal.solve import clear_caches, solve_translation, switch_times

__all__ = [
    "ArcKind",
    "BenchmarkLimits",
    "InputArc",
    "SolveStatus",
    "TimeOptimalSolution",
    "clear_caches",
    "solve_translation",
    "switch_times",
]
