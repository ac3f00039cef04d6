"""An independent formulation of the physics, the oracle the compiled kernels are tested against.

The package computes kinematics, dynamics, closure rows and the fixed-step methods only in the
compiled scalar kernels (:mod:`vjm_ros.core.kernels`: one recursion along each chain for frames,
rates and bias accelerations, ``M = sum m J^T J + I Jw^T Jw``, ``b = sum J^T m (Jdot qd - g)``,
loop-written LU, Cholesky and Jacobi solves). These modules derive the same physics
(docs/design.md sections 1-3) another way, from the scene description, so that a slip in either
shows as a disagreement:

* :mod:`oracle.kinematics`: the chain loop of section 1 for the frames; point velocities and
  ``Jdot qd`` summed over the joint columns of each point (``e_z x (P - O_k)`` or ``n_pred``)
  and their time derivatives, not propagated link to link;
* :mod:`oracle.dynamics`: ``b`` and the columns of ``M`` by the recursive Newton-Euler method
  (link forces and moments, outward motion and inward balance); the energies by their
  definitions; solves through a Cholesky factor of ``M``;
* :mod:`oracle.constraints`: closure rows from the closure points' positions, columns and bias
  accelerations; exact multipliers, least changes and velocity projection through the singular
  values of the whitened Jacobian ``A L^-T`` (``M = L L^T``);
* :mod:`oracle.mechanism`: the closed mechanism with the package mechanism's interface;
* :mod:`oracle.fixed`: explicit and semi-implicit Euler as their two lines, RK4 as a Butcher
  tableau run by a generic explicit Runge-Kutta step on ``(q, qd)``, implicit Euler as a Newton
  solve of the backward-Euler equation in the penalty forces;
* :mod:`oracle.closed_model`: the controllers' reduced dynamics, from the modules above.

Shared with the package: the model (:class:`vjm_ros.core.model.Model`) and the closure settings
(:class:`~vjm_ros.core.constraints.PenaltyClosure`, :class:`~vjm_ros.core.constraints.ExactClosure`).
Besides the kernels, ``test/test_dynamics.py`` and ``test/test_closures.py`` check this oracle
against finite differences of the geometry of ``test/chains.py``.
"""
