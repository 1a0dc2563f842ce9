"""SoftRas's mesh regularizers: the Laplacian and flatten losses."""

import numpy as np
import torch
import torch.nn as nn

__all__ = ["LaplacianLoss", "FlattenLoss"]


def _faces_numpy(faces):
    if torch.is_tensor(faces):
        faces = faces.detach().cpu().numpy()
    return np.asarray(faces).astype(np.int64)


class LaplacianLoss(nn.Module):
    """Squared uniform Laplacian of the vertices: ``Σ_i |x_i - mean_{j ~ i} x_j|²`` per mesh.

    The operator is SoftRas's dense [V, V] matrix (the buffer ``laplacian``, so that state
    dicts of SoftRas models load): 1 on the diagonal, ``-1 / deg(i)`` for the neighbours of
    vertex i.
    """

    def __init__(self, vertex, faces, average=False):
        """
        Args:
            vertex: [V, 3], the template's vertices (only V is used).
            faces: [F, 3] indices (tensor or array).
            average: ``forward`` returns the batch's mean instead of one value per mesh.
        """
        super(LaplacianLoss, self).__init__()
        self.nv = vertex.size(0)
        self.nf = faces.size(0) if torch.is_tensor(faces) else len(faces)
        self.average = average
        f = _faces_numpy(faces)

        laplacian = np.zeros([self.nv, self.nv], dtype=np.float32)
        for a, b in ((0, 1), (1, 2), (2, 0)):
            laplacian[f[:, a], f[:, b]] = -1
            laplacian[f[:, b], f[:, a]] = -1
        degree = -laplacian.sum(1)
        np.fill_diagonal(laplacian, degree)
        # A vertex no face uses keeps a zero row (SoftRas divided 0 by 0 there).
        scale = np.where(degree > 0, degree, 1).astype(np.float32)
        laplacian /= scale[:, None]
        self.register_buffer("laplacian", torch.from_numpy(laplacian))

    def forward(self, x):
        """[batch, V, 3] -> [batch] losses (a scalar with ``average``)."""
        batch_size = x.size(0)
        x = torch.matmul(self.laplacian.to(x.dtype), x)
        dims = tuple(range(x.ndimension())[1:])
        x = x.pow(2).sum(dims)
        if self.average:
            return x.sum() / batch_size
        return x


class FlattenLoss(nn.Module):
    """Flatness across edges: ``Σ_edges (cos θ + 1)²`` per mesh, θ the angle between the two
    faces' in-plane directions away from the shared edge (π for a flat pair).

    Each edge shared by exactly two faces is one term, with its vertices in the buffers ``v0s``,
    ``v1s`` (the edge) and ``v2s``, ``v3s`` (the opposite corners), as SoftRas. Boundary edges
    (one face) and non-manifold edges (more than two) have no such pair and are left out; in
    SoftRas they misaligned the buffers.
    """

    def __init__(self, faces, average=False):
        """
        Args:
            faces: [F, 3] indices (tensor or array).
            average: ``forward`` returns the batch's mean instead of one value per mesh.
        """
        super(FlattenLoss, self).__init__()
        self.nf = faces.size(0) if torch.is_tensor(faces) else len(faces)
        self.average = average
        f = _faces_numpy(faces)

        # Every (edge, opposite corner) of every face, the edge as (low, high) index.
        edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=0)
        opposite = np.concatenate([f[:, 2], f[:, 0], f[:, 1]], axis=0)
        face_index = np.tile(np.arange(len(f)), 3)
        edges = np.sort(edges, axis=1)
        # Group by edge (sorted), faces in file order within an edge.
        order = np.lexsort((face_index, edges[:, 1], edges[:, 0]))
        edges, opposite = edges[order], opposite[order]
        starts = np.concatenate([[True], np.any(edges[1:] != edges[:-1], axis=1)])
        group = np.cumsum(starts) - 1
        counts = np.bincount(group)
        first = np.nonzero(starts)[0]
        paired = first[counts == 2]

        self.register_buffer("v0s", torch.from_numpy(edges[paired, 0]).long())
        self.register_buffer("v1s", torch.from_numpy(edges[paired, 1]).long())
        self.register_buffer("v2s", torch.from_numpy(opposite[paired]).long())
        self.register_buffer("v3s", torch.from_numpy(opposite[paired + 1]).long())

    def forward(self, vertices, eps=1e-6):
        """[batch, V, 3] -> [batch] losses (a scalar with ``average``)."""
        batch_size = vertices.size(0)
        v0s = vertices[:, self.v0s, :]
        v1s = vertices[:, self.v1s, :]
        v2s = vertices[:, self.v2s, :]
        v3s = vertices[:, self.v3s, :]

        # SoftRas's formulation, eps and all: the components of v2 - v0 and v3 - v0
        # perpendicular to the edge, and the cosine between them.
        a1 = v1s - v0s
        b1 = v2s - v0s
        a1l2 = a1.pow(2).sum(-1)
        b1l2 = b1.pow(2).sum(-1)
        a1l1 = (a1l2 + eps).sqrt()
        b1l1 = (b1l2 + eps).sqrt()
        ab1 = (a1 * b1).sum(-1)
        cos1 = ab1 / (a1l1 * b1l1 + eps)
        sin1 = (1 - cos1.pow(2) + eps).sqrt()
        c1 = a1 * (ab1 / (a1l2 + eps))[:, :, None]
        cb1 = b1 - c1
        cb1l1 = b1l1 * sin1

        a2 = v1s - v0s
        b2 = v3s - v0s
        a2l2 = a2.pow(2).sum(-1)
        b2l2 = b2.pow(2).sum(-1)
        a2l1 = (a2l2 + eps).sqrt()
        b2l1 = (b2l2 + eps).sqrt()
        ab2 = (a2 * b2).sum(-1)
        cos2 = ab2 / (a2l1 * b2l1 + eps)
        sin2 = (1 - cos2.pow(2) + eps).sqrt()
        c2 = a2 * (ab2 / (a2l2 + eps))[:, :, None]
        cb2 = b2 - c2
        cb2l1 = b2l1 * sin2

        cos = (cb1 * cb2).sum(-1) / (cb1l1 * cb2l1 + eps)

        dims = tuple(range(cos.ndimension())[1:])
        loss = (cos + 1).pow(2).sum(dims)
        if self.average:
            return loss.sum() / batch_size
        return loss
