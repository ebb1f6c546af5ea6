import numpy as np

from fusiongs.camera.tum import matrix_to_quat_xyzw, quat_xyzw_to_matrix


def _reference_quat_xyzw(R: np.ndarray) -> np.ndarray:
    """Slow reference: eigenvector of Bar-Itzhack's symmetric 4x4 matrix, one matrix at a time."""
    out = []
    for m in R.reshape(-1, 3, 3):
        (a, b, c), (d, e, f), (g, h, i) = m
        K = np.array([[a - e - i, d + b, g + c, h - f],
                      [d + b, e - a - i, h + f, c - g],
                      [g + c, h + f, i - a - e, d - b],
                      [h - f, c - g, d - b, a + e + i]]) / 3.0
        w, v = np.linalg.eigh(K)
        q = v[:, np.argmax(w)]
        out.append(q if q[3] >= 0 else -q)
    return np.array(out).reshape(R.shape[:-2] + (4,))


def test_vectorised_matrix_to_quat_matches_slow_reference(rng):
    q = rng.standard_normal((300, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    R = quat_xyzw_to_matrix(q)
    assert np.allclose(matrix_to_quat_xyzw(R), _reference_quat_xyzw(R), atol=1e-10)


def test_matrix_to_quat_handles_180_degree_turns_and_batch_shapes():
    R = np.stack([np.eye(3), np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])])
    q = matrix_to_quat_xyzw(R.reshape(2, 2, 3, 3))
    assert q.shape == (2, 2, 4)
    assert np.allclose(np.abs(q.reshape(4, 4)), np.eye(4)[[3, 0, 1, 2]])
    assert matrix_to_quat_xyzw(np.eye(3)).shape == (4,)
