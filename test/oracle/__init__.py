"""An independent numpy formulation of the physics, the oracle the compiled kernels are tested
against (as MuJoCo's MJX is tested against its C library).

The package computes kinematics, dynamics, closure rows and the fixed-step methods only in the
compiled scalar kernels (:mod:`vjm_ros.core.kernels`); these modules write the same physics
(docs/design.md sections 1-3) with whole-array numpy operations and LAPACK solves:

* :mod:`oracle.kinematics`: link frames, point motion and Jacobians from the ancestor matrix;
* :mod:`oracle.dynamics`: ``M``, ``b`` and the energies (Kane's equations);
* :mod:`oracle.constraints`: closure rows, penalty forces, exact multipliers, projection;
* :mod:`oracle.mechanism`: the closed mechanism with the package mechanism's interface;
* :mod:`oracle.fixed`: the fixed-step methods as plain loops;
* :mod:`oracle.closed_model`: the operational-space model of the controllers.

Only the model (:class:`vjm_ros.core.model.Model`) and the settings classes are shared with the
package.
"""
