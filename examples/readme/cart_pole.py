import numpy as np
import trellis_mech as tm

scene = tm.load_scene("examples/scenes/cart_pole.json")        # the upright cart-pole
lin = tm.linearize(scene.model, scene.q, scene.dq, scene.u)    # exact A (4, 4), B (4, 1)
print("states:", scene.model.state_names)
print("open loop eigenvalues:", np.sort_complex(np.linalg.eigvals(lin.A)))
lqr = tm.solve_care(lin.A, lin.B, np.eye(4), np.eye(1))        # balancing gain K (1, 4)
assert lqr.ok, lqr.describe()
print("K =", lqr.K, "\nclosed loop:", np.sort_complex(lqr.closed_loop_eigenvalues))
