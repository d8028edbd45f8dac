"""The declared noise model carried to each frame's residual (issue #17): its covariance
and the whitened residual, whose squared norm is chi-square distributed when the model
explains the data.

A frame's 11 residual rows (6 inter-foot, 5 flat-ground) are functions of its n
encoder angles (n the leg joints) and of the IMU's vertical (2 tilt angles), so to first
order their covariance is

    Sigma_k = sigma_q^2 G_k G_k^T + sigma_t^2 H_k H_k^T,

G_k (11, n) the rows' Jacobian w.r.t. the joint angles (the offsets' Jacobian with the
segment mean held), H_k (11, 2) w.r.t. the IMU's roll and pitch (the `imu_tilt`
effect's columns). Only 8 rows are independent (the height row and the right sole's
tilt are functions of the others), so Sigma_k has rank 8: the whitening keeps its range,

    z_k = U diag(lambda^-1/2) U^T r_k   (eigenpairs with lambda above `RANK_RTOL` lambda_max),

the symmetric square root, so z_k's rows stay the residual's channels (for tracing);
|z_k|^2 ~ chi2(rank_k) for pure noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RANK_RTOL = 1e-6  # eigenvalues below this fraction of a frame's largest are the rows' dependence, not noise
# The 11 rows of a frame, by channel (tracing reads these names).
ROW_CHANNELS = ("feet_translation",) * 3 + ("feet_rotation",) * 3 + ("flat_height",) + ("sole_tilt_left",) * 2 \
    + ("sole_tilt_right",) * 2


@dataclass(frozen=True)
class Whitened:
    """Whitened residuals of N frames: z (N, 11) in the residual's channels, the rank of
    each frame's covariance and the chi-square per frame."""

    z: np.ndarray
    rank: np.ndarray

    @property
    def chi2(self) -> np.ndarray:
        return (self.z**2).sum(axis=1)


def frame_covariances(G: np.ndarray, H: np.ndarray, sigma_q: float, sigma_t: float) -> np.ndarray:
    """(N, 11, 11) first-order covariances of each frame's rows from encoder noise
    `sigma_q` (rad, every joint) and IMU tilt noise `sigma_t` (rad, roll and pitch)."""
    return sigma_q**2 * G @ G.transpose(0, 2, 1) + sigma_t**2 * H @ H.transpose(0, 2, 1)


def whitening(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(W (N, 11, 11), rank (N,)): each covariance's symmetric inverse square root on its
    range."""
    lam, U = np.linalg.eigh(cov)
    keep = lam > RANK_RTOL * lam[:, -1:]
    inv_sqrt = np.where(keep, 1.0 / np.sqrt(np.where(keep, lam, 1.0)), 0.0)
    return (U * inv_sqrt[:, None, :]) @ U.transpose(0, 2, 1), keep.sum(axis=1)


def whiten(r: np.ndarray, cov: np.ndarray) -> Whitened:
    """Whiten frame residuals r (N, 11) by their covariances (N, 11, 11)."""
    W, rank = whitening(cov)
    return Whitened(np.einsum("nij,nj->ni", W, r), rank)


def whitened_system(r: np.ndarray, J: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frames' residuals r (N, 11) and Jacobians J (N, 11, k) whitened by W (N, 11, 11,
    `whitening` of their covariances), stacked: (z (11 N,), Jw (11 N, k)). The
    generalized least-squares problem min |z - Jw dx|^2 weighs every frame by its own
    noise, the rows' correlations included."""
    return np.einsum("nij,nj->ni", W, r).ravel(), np.einsum("nij,njk->nik", W, J).reshape(-1, J.shape[2])


def expected_rows(cov: np.ndarray) -> np.ndarray:
    """(N, 11) E[z_i^2] of each whitened row under the noise model: the diagonal of the
    projector on the covariance's range (the rows share the rank, so not 1 each)."""
    W, _ = whitening(cov)
    P = W @ cov @ W.transpose(0, 2, 1)
    return np.diagonal(P, axis1=1, axis2=2).copy()
