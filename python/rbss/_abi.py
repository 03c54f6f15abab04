# The C ABI's table for the ctypes layer (python/rbss/__init__.py), written from
# ffi/abi/src/lib.rs (rbss-abi): do not edit. `RBSS_BLESS=1 cargo test --release -p
# rbss-ffi --test abi` rewrites it; that test fails when it is stale.

ABI_VERSION = 4

RBSS_OK = 0
RBSS_ERR_SOLVER = 1
RBSS_ERR_ARGUMENT = 2
RBSS_ERR_NO_DYNAMICS = 3
RBSS_ERR_PANIC = 4
RBSS_ERR_STATE = 5
RBSS_ERR_NONFINITE = 6
RBSS_METHOD_DOPRI5 = 0
RBSS_METHOD_DOP853 = 1
RBSS_LINEARIZE_OUTPUTS = 0
RBSS_LINEARIZE_ACTUATED = 1
RBSS_STEP_RK4 = 0
RBSS_STEP_SEMI_IMPLICIT_EULER = 1
RBSS_COORDINATES = 0
RBSS_CONSTRAINTS = 1
RBSS_ACTUATED = 2
RBSS_OUTPUTS = 3
RBSS_DYNAMICS = 4

# name: (return kind, ((argument, kind, length or None), ...)); the kinds as in rbss-abi.
FUNCTIONS = {
    "rbss_abi_version": ("u32", ()),
    "rbss_new": ("handle", ()),
    "rbss_free": ("void", (("h", "handle", None),)),
    "rbss_last_error": ("string", (("h", "handle_const", None),)),
    "rbss_size": ("size", (("h", "handle_const", None), ("what", "int", None))),
    "rbss_name": ("string", (("h", "handle_const", None),)),
    "rbss_coordinate": ("string", (("h", "handle_const", None), ("i", "size", None))),
    "rbss_constraint": ("string", (("h", "handle_const", None), ("i", "size", None))),
    "rbss_actuated": ("size", (("h", "handle_const", None), ("i", "size", None))),
    "rbss_output": ("size", (("h", "handle_const", None), ("i", "size", None))),
    "rbss_home": ("int", (("h", "handle", None), ("x", "output", "n"))),
    "rbss_ik": ("int", (("h", "handle", None), ("pose", "input", "outputs"), ("x_start", "input_or_null", "n"), ("x", "output", "n"))),
    "rbss_fk": ("int", (("h", "handle", None), ("q", "input", "actuated"), ("x_start", "input_or_null", "n"), ("x", "output", "n"))),
    "rbss_inverse_velocity": ("int", (("h", "handle", None), ("x", "input", "n"), ("pose_dot", "input", "outputs"), ("xdot", "output", "n"))),
    "rbss_forward_velocity": ("int", (("h", "handle", None), ("x", "input", "n"), ("qdot", "input", "actuated"), ("xdot", "output", "n"))),
    "rbss_inverse_acceleration": ("int", (("h", "handle", None), ("x", "input", "n"), ("xdot", "input", "n"), ("pose_ddot", "input", "outputs"), ("xddot", "output", "n"))),
    "rbss_forward_acceleration": ("int", (("h", "handle", None), ("x", "input", "n"), ("xdot", "input", "n"), ("qddot", "input", "actuated"), ("xddot", "output", "n"))),
    "rbss_inverse_dynamics": ("int", (("h", "handle", None), ("x", "input", "n"), ("xdot", "input", "n"), ("xddot", "input", "n"), ("u", "output", "actuated"), ("lambda", "output", "m"))),
    "rbss_forward_dynamics": ("int", (("h", "handle", None), ("x", "input", "n"), ("xdot", "input", "n"), ("u", "input", "actuated"), ("xddot", "output", "n"), ("lambda", "output", "m"))),
    "rbss_forward_dynamics_batch": ("int", (("h", "handle", None), ("count", "size", None), ("x", "input", "count x n"), ("xdot", "input", "count x n"), ("u", "input", "count x actuated"), ("xddot", "output", "count x n"), ("lambda", "output", "count x m"))),
    "rbss_simulate": ("int", (("h", "handle", None), ("x0", "input", "n"), ("xdot0", "input", "n"), ("u", "input_or_null", "actuated"), ("t_end", "double", None), ("rtol", "double", None), ("atol", "double", None), ("x", "output", "n"), ("xdot", "output", "n"))),
    "rbss_simulate_method": ("int", (("h", "handle", None), ("method", "int", None), ("x0", "input", "n"), ("xdot0", "input", "n"), ("u", "input_or_null", "actuated"), ("t_end", "double", None), ("rtol", "double", None), ("atol", "double", None), ("x", "output", "n"), ("xdot", "output", "n"))),
    "rbss_simulate_checked": ("int", (("h", "handle", None), ("method", "int", None), ("x0", "input", "n"), ("xdot0", "input", "n"), ("u", "input_or_null", "actuated"), ("t_end", "double", None), ("rtol", "double", None), ("atol", "double", None), ("state_tol", "double", None), ("project", "int", None), ("x", "output", "n"), ("xdot", "output", "n"), ("state", "output", "4"))),
    "rbss_energy": ("int", (("h", "handle", None), ("x", "input", "n"), ("xdot", "input", "n"), ("out", "output", "2"))),
    "rbss_constraints": ("int", (("h", "handle", None), ("x", "input", "n"), ("f", "output", "m"))),
    "rbss_jacobian": ("int", (("h", "handle", None), ("x", "input", "n"), ("g", "output", "m x n"))),
    "rbss_gamma": ("int", (("h", "handle", None), ("x", "input", "n"), ("xdot", "input", "n"), ("gamma", "output", "m"))),
    "rbss_mass_matrix": ("int", (("h", "handle", None), ("x", "input", "n"), ("mass", "output", "n x n"))),
    "rbss_psi": ("int", (("h", "handle", None), ("x", "input", "n"), ("xdot", "input", "n"), ("psi", "output", "n"))),
    "rbss_forward_dynamics_derivatives": ("int", (("h", "handle", None), ("x", "input", "n"), ("xdot", "input", "n"), ("u", "input", "actuated"), ("xddot", "output", "n"), ("lambda", "output", "m"), ("dxddot_dx", "output", "n x n"), ("dxddot_dxdot", "output", "n x n"), ("dxddot_du", "output", "n x actuated"), ("dlambda_dx", "output", "m x n"), ("dlambda_dxdot", "output", "m x n"), ("dlambda_du", "output", "m x actuated"))),
    "rbss_inverse_dynamics_derivatives": ("int", (("h", "handle", None), ("x", "input", "n"), ("xdot", "input", "n"), ("xddot", "input", "n"), ("u", "output", "actuated"), ("lambda", "output", "m"), ("du_dx", "output", "actuated x n"), ("du_dxdot", "output", "actuated x n"), ("du_dxddot", "output", "actuated x n"), ("dlambda_dx", "output", "m x n"), ("dlambda_dxdot", "output", "m x n"), ("dlambda_dxddot", "output", "m x n"))),
    "rbss_linearize": ("int", (("h", "handle", None), ("coordinates", "int", None), ("x", "input", "n"), ("xdot", "input", "n"), ("u", "input", "actuated"), ("a", "output", "(2 * (n - m)) x(2 * (n - m))"), ("b", "output", "(2 * (n - m)) x actuated"))),
    "rbss_step_derivatives": ("int", (("h", "handle", None), ("method", "int", None), ("x", "input", "n"), ("xdot", "input", "n"), ("u", "input", "actuated"), ("dt", "double", None), ("baumgarte", "input_or_null", "2"), ("x_next", "output", "n"), ("xdot_next", "output", "n"), ("fx", "output", "(2 * n) x(2 * n)"), ("fu", "output", "(2 * n) x actuated"))),
}
