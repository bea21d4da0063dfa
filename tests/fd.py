"""Central finite differences shared by the force tests."""
import numpy as np


def fd_jacobian(fun, z, eps):
    """d fun / d z by central differences, fun mapping an array to an array."""
    z = z.copy()
    flat = z.reshape(-1)
    J = None
    for q in range(z.size):
        old = flat[q]
        flat[q] = old + eps
        fp = np.asarray(fun(z)).reshape(-1)
        flat[q] = old - eps
        fm = np.asarray(fun(z)).reshape(-1)
        flat[q] = old
        if J is None:
            J = np.zeros((fp.size, z.size))
        J[:, q] = (fp - fm) / (2 * eps)
    return J
