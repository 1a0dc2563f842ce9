"""Batched triangle meshes with SoftRas textures."""

import copy

import numpy as np
import torch
import torch.nn.functional as F

from .. import _checks
from . import functional as srf
from .functional._convert import float_dtype

__all__ = ["Mesh"]


class Mesh(object):
    """A batch of triangle meshes of equal vertex and face counts, with textures.

    Attributes:
        vertices: [batch, V, 3] float.
        faces: [batch, F, 3] integer (int32 from files and numpy).
        textures: [batch, F, R², 3] (``texture_type='surface'``: R×R texels per face, SoftRas's
            layout) or [batch, V, 3] (``'vertex'``: a colour per vertex).
        texture_type: ``'surface'`` or ``'vertex'``.
        texture_res: R (1 for vertex textures).
        device: the vertices' device.
        batch_size, num_vertices, num_faces: sizes.

    Derived quantities (``face_vertices``, ``surface_normals``, ``vertex_normals``) are cached
    and recomputed after ``vertices`` or ``faces`` is assigned. Nothing here assumes CUDA:
    numpy inputs become CPU tensors, and ``to``, ``cuda`` and ``cpu`` move the mesh.
    """

    def __init__(self, vertices, faces, textures=None, texture_res=1, texture_type="surface"):
        """
        Args:
            vertices: [batch, V, 3] or [V, 3] (tensor or numpy array).
            faces: [batch, F, 3] or [F, 3] indices (tensor or numpy array).
            textures: ``None`` (white), or [batch, F, R², 3] / [F, R², 3] surface textures, or
                [batch, V, 3] / [V, 3] vertex colours (tensor or numpy array).
            texture_res: R of the white surface textures made when ``textures`` is ``None``.
            texture_type: ``'surface'`` or ``'vertex'``.
        """
        if texture_type not in ("surface", "vertex"):
            raise ValueError("texture_type must be 'surface' or 'vertex', got %r" % (texture_type,))
        if isinstance(vertices, np.ndarray):
            vertices = torch.from_numpy(vertices).float()
        if isinstance(faces, np.ndarray):
            _checks.integer_faces("faces", faces)  # .int() would truncate float indices
            faces = torch.from_numpy(faces).int().to(vertices.device)
        if vertices.ndimension() == 2:
            vertices = vertices[None, :, :]
        if faces.ndimension() == 2:
            faces = faces[None, :, :]
        self._vertices = vertices
        self._faces = faces

        self.device = vertices.device
        self.texture_type = texture_type
        self.batch_size = vertices.shape[0]
        self.num_vertices = vertices.shape[1]
        self.num_faces = faces.shape[1]

        self._face_vertices = None
        self._face_vertices_update = True
        self._surface_normals = None
        self._surface_normals_update = True
        self._vertex_normals = None
        self._vertex_normals_update = True
        self._fill_back = False

        dtype = float_dtype(vertices)
        if textures is None:
            if texture_type == "surface":
                textures = torch.ones(self.batch_size, self.num_faces, texture_res ** 2, 3,
                                      dtype=dtype, device=self.device)
                self.texture_res = texture_res
            else:
                textures = torch.ones(self.batch_size, self.num_vertices, 3,
                                      dtype=dtype, device=self.device)
                self.texture_res = 1
        else:
            if isinstance(textures, np.ndarray):
                textures = torch.from_numpy(textures).float().to(self.device)
            if textures.ndimension() == 3 and texture_type == "surface":
                textures = textures[None, :, :, :]
            if textures.ndimension() == 2 and texture_type == "vertex":
                textures = textures[None, :, :]
            self.texture_res = int(np.sqrt(textures.shape[2]))
        self._textures = textures

        self._origin_vertices = self._vertices
        self._origin_faces = self._faces
        self._origin_textures = self._textures

    # -- geometry and textures ------------------------------------------------------------------

    @property
    def faces(self):
        """[batch, F, 3] vertex indices."""
        return self._faces

    @faces.setter
    def faces(self, faces):
        self._faces = faces
        self.num_faces = faces.shape[1]
        self._invalidate()

    @property
    def vertices(self):
        """[batch, V, 3] positions."""
        return self._vertices

    @vertices.setter
    def vertices(self, vertices):
        self._vertices = vertices
        self.num_vertices = vertices.shape[1]
        self._invalidate()

    @property
    def textures(self):
        """[batch, F, R², 3] surface textures or [batch, V, 3] vertex colours."""
        return self._textures

    @textures.setter
    def textures(self, textures):
        self._textures = textures

    def _invalidate(self):
        self._face_vertices_update = True
        self._surface_normals_update = True
        self._vertex_normals_update = True

    @property
    def face_vertices(self):
        """[batch, F, 3, 3]: the corners of every face."""
        if self._face_vertices_update:
            self._face_vertices = srf.face_vertices(self.vertices, self.faces)
            self._face_vertices_update = False
        return self._face_vertices

    @property
    def surface_normals(self):
        """[batch, F, 3] unit face normals ``normalize(cross(v2 - v1, v0 - v1))`` (SPEC §1)."""
        if self._surface_normals_update:
            fv = self.face_vertices
            v10 = fv[:, :, 0] - fv[:, :, 1]
            v12 = fv[:, :, 2] - fv[:, :, 1]
            self._surface_normals = F.normalize(torch.cross(v12, v10, dim=-1), p=2, dim=2, eps=1e-6)
            self._surface_normals_update = False
        return self._surface_normals

    @property
    def vertex_normals(self):
        """[batch, V, 3] unit vertex normals (``functional.vertex_normals``)."""
        if self._vertex_normals_update:
            self._vertex_normals = srf.vertex_normals(self.vertices, self.faces)
            self._vertex_normals_update = False
        return self._vertex_normals

    @property
    def face_textures(self):
        """The textures per face, as the rasterizer takes them: [batch, F, R², 3] for surface
        textures, [batch, F, 3, 3] corner colours for vertex textures."""
        if self.texture_type == "surface":
            return self.textures
        if self.texture_type == "vertex":
            return srf.face_vertices(self.textures, self.faces)
        raise ValueError("texture type not applicable")

    # -- in-place edits -------------------------------------------------------------------------

    def fill_back_(self):
        """Appends every face again with the opposite winding (and its texture), once."""
        if not self._fill_back:
            self.faces = torch.cat((self.faces, self.faces[:, :, [2, 1, 0]]), dim=1)
            self.textures = torch.cat((self.textures, self.textures), dim=1)
            self._fill_back = True

    def reset_(self):
        """Restores the vertices, faces and textures the mesh was made with."""
        self.vertices = self._origin_vertices
        self.faces = self._origin_faces
        self.textures = self._origin_textures
        self._fill_back = False

    def _shallow_copy(self):
        """A mesh sharing this one's tensors, whose attributes can be reassigned (as lighting
        and transforms do) without touching this one."""
        return copy.copy(self)

    # -- devices --------------------------------------------------------------------------------

    _TENSORS = ("_vertices", "_faces", "_textures",
                "_origin_vertices", "_origin_faces", "_origin_textures")

    def to(self, device=None, dtype=None):
        """Moves the mesh to ``device`` and casts its floating tensors (vertices, textures) to
        ``dtype``, in place, like ``torch.nn.Module.to``; faces keep their integer dtype.

        ``mesh.to(torch.float64)`` is also accepted. Differentiable: gradients flow back to the
        tensors the mesh held before. Returns the mesh.
        """
        if isinstance(device, torch.dtype):
            device, dtype = None, device
        for name in self._TENSORS:
            tensor = getattr(self, name)
            if tensor is None:
                continue
            target_dtype = dtype if (dtype is not None and tensor.is_floating_point()) else None
            setattr(self, name, tensor.to(device=device, dtype=target_dtype))
        self.device = self._vertices.device
        self._invalidate()
        return self

    def cuda(self, device=None):
        """Moves the mesh to a CUDA device (``device``: index or ``None`` for the current one);
        returns the mesh."""
        return self.to(torch.device("cuda") if device is None else torch.device("cuda", device))

    def cpu(self):
        """Moves the mesh to the CPU; returns the mesh."""
        return self.to(torch.device("cpu"))

    # -- files ----------------------------------------------------------------------------------

    @classmethod
    def from_obj(cls, filename_obj, normalization=False, load_texture=False, texture_res=1,
                 texture_type="surface"):
        """A mesh (batch of one) from a Wavefront OBJ file (``functional.load_obj``).

        Args:
            filename_obj: path of the ``.obj``.
            normalization: fit the mesh into [-1, 1], centred.
            load_texture: read textures (surface: from the MTL; vertex: ``v x y z r g b``);
                otherwise white.
            texture_res: R, texels per face side.
            texture_type: ``'surface'`` or ``'vertex'``.
        """
        if load_texture:
            vertices, faces, textures = srf.load_obj(filename_obj, normalization=normalization,
                                                     texture_res=texture_res, load_texture=True,
                                                     texture_type=texture_type)
        else:
            vertices, faces = srf.load_obj(filename_obj, normalization=normalization,
                                           texture_res=texture_res, load_texture=False)
            textures = None
        return cls(vertices, faces, textures, texture_res, texture_type)

    def save_obj(self, filename_obj, save_texture=False, texture_res_out=16):
        """Writes the mesh (batch of one) as OBJ (``functional.save_obj``); with
        ``save_texture`` also its textures (a ``texture_res_out`` atlas for surface textures)."""
        if self.batch_size != 1:
            raise ValueError("Could not save when batch size >= 1")
        if save_texture:
            srf.save_obj(filename_obj, self.vertices[0], self.faces[0],
                         textures=self.textures[0], texture_res=texture_res_out,
                         texture_type=self.texture_type)
        else:
            srf.save_obj(filename_obj, self.vertices[0], self.faces[0], textures=None)

    def voxelize(self, voxel_size=32):
        """[batch, s, s, s] int32 occupancy (``functional.voxelization``) of the mesh scaled by
        ``s / (s - 1)`` and moved by +0.5, as SoftRas: meant for vertices in about [-0.5, 0.5]³."""
        face_vertices_norm = self.face_vertices * voxel_size / (voxel_size - 1) + 0.5
        return srf.voxelization(face_vertices_norm, voxel_size, False)
