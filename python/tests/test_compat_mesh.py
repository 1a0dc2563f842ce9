"""softvk.soft_renderer's meshes and files: Mesh, face_vertices, vertex_normals, load_obj,
save_obj. None of these tests needs the renderer."""

import os
import pathlib

import numpy as np
import pytest
import torch

import softvk.soft_renderer as sr
import softvk.soft_renderer.functional as srf
from softvk.soft_renderer.functional import _image
from softvk.soft_renderer.functional.load_obj import texel_center_barycentrics


def assets_dir():
    env = os.environ.get("SOFTVK_ASSETS")
    if env:
        return pathlib.Path(env)
    return pathlib.Path(__file__).resolve().parent / ".." / ".." / "assets"


SPHERE = assets_dir() / "sphere_642.obj"
SPOT = assets_dir() / "spot_triangulated.obj"


def obj_lines(path, kind):
    with open(path) as f:
        return [line.split()[1:] for line in f if line.split()[:1] == [kind]]


def random_mesh(batch=2, nv=9, nf=14, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    vertices = torch.randn(batch, nv, 3, generator=g, dtype=dtype)
    faces = torch.stack([torch.randperm(nv, generator=g)[:3] for _ in range(batch * nf)])
    return vertices, faces.reshape(batch, nf, 3).int()


# -- face_vertices / vertex_normals ----------------------------------------------------------------

def test_face_vertices_matches_a_direct_loop():
    vertices, faces = random_mesh()
    out = srf.face_vertices(vertices, faces)
    assert out.shape == (2, 14, 3, 3)
    for b in range(2):
        for f in range(14):
            for k in range(3):
                assert torch.equal(out[b, f, k], vertices[b, faces[b, f, k]])


def test_face_vertices_rejects_mismatched_batches():
    vertices, faces = random_mesh()
    with pytest.raises(ValueError):
        srf.face_vertices(vertices[:1], faces)


def test_vertex_normals_match_a_direct_loop():
    vertices, faces = random_mesh(nv=7, nf=10, seed=3)
    out = srf.vertex_normals(vertices, faces)
    v, f = vertices.numpy(), faces.numpy()
    for b in range(2):
        sums = np.zeros((7, 3))
        for a, c, d in f[b]:
            # SPEC §1: the un-normalized face normal cross(v2 - v1, v0 - v1).
            n = np.cross(v[b, d] - v[b, c], v[b, a] - v[b, c])
            for i in (a, c, d):
                sums[i] += n
        lengths = np.linalg.norm(sums, axis=1, keepdims=True)
        expected = sums / np.maximum(lengths, 1e-6)
        assert np.allclose(out[b].numpy(), expected, atol=1e-12)


def test_vertex_normals_of_the_sphere_point_outward():
    vertices, faces = srf.load_obj(str(SPHERE))
    normals = srf.vertex_normals(vertices[None], faces[None])[0]
    radial = torch.nn.functional.normalize(vertices, dim=1)
    assert (normals * radial).sum(1).min() > 0.99


# -- Mesh ------------------------------------------------------------------------------------------

def test_mesh_batches_unbatched_numpy_inputs_on_the_cpu():
    vertices = np.random.RandomState(0).rand(5, 3)
    faces = np.array([[0, 1, 2], [2, 3, 4]])
    mesh = sr.Mesh(vertices, faces)
    assert mesh.vertices.shape == (1, 5, 3) and mesh.vertices.dtype == torch.float32
    assert mesh.faces.shape == (1, 2, 3) and mesh.faces.dtype == torch.int32
    assert mesh.device == torch.device("cpu")
    assert mesh.textures.shape == (1, 2, 1, 3) and bool((mesh.textures == 1).all())
    assert (mesh.batch_size, mesh.num_vertices, mesh.num_faces, mesh.texture_res) == (1, 5, 2, 1)

    vertex_mesh = sr.Mesh(vertices, faces, textures=np.random.rand(5, 3), texture_type="vertex")
    assert vertex_mesh.textures.shape == (1, 5, 3)
    face_textures = vertex_mesh.face_textures
    assert face_textures.shape == (1, 2, 3, 3)
    assert torch.equal(face_textures[0, 1, 2], vertex_mesh.textures[0, 4])
    with pytest.raises(ValueError):
        sr.Mesh(vertices, faces, texture_type="texel")


def test_mesh_caches_follow_vertex_assignment_and_reset_restores():
    vertices, faces = random_mesh(batch=1, seed=5)
    mesh = sr.Mesh(vertices, faces)
    fv = mesh.face_vertices
    assert torch.equal(fv, srf.face_vertices(vertices, faces))
    mesh.vertices = vertices * 2
    assert torch.allclose(mesh.face_vertices, 2 * fv)
    assert torch.allclose(mesh.vertex_normals, srf.vertex_normals(vertices, faces))
    mesh.fill_back_()
    assert mesh.num_faces == 28 and mesh.textures.shape[1] == 28
    assert torch.equal(mesh.faces[0, 14:], faces[0][:, [2, 1, 0]])
    mesh.reset_()
    assert torch.equal(mesh.vertices, vertices) and mesh.num_faces == 14


def test_mesh_surface_normals_follow_spec_winding():
    mesh = sr.Mesh(torch.tensor([[0.0, 0, 0], [0, 0, 1], [1, 0, 0]]), torch.tensor([[0, 1, 2]]))
    assert np.allclose(mesh.surface_normals[0, 0].numpy(), [0, 1, 0])


def test_mesh_to_casts_floats_and_keeps_integer_faces():
    mesh = sr.Mesh.from_obj(str(SPHERE))
    assert mesh.to(torch.float64) is mesh
    assert mesh.vertices.dtype == torch.float64 and mesh.textures.dtype == torch.float64
    assert mesh.faces.dtype == torch.int32
    assert mesh.cpu().device == torch.device("cpu")
    assert mesh.face_vertices.dtype == torch.float64


# -- load_obj --------------------------------------------------------------------------------------

def test_load_obj_sphere_shapes_dtypes_and_file_order():
    vertices, faces = srf.load_obj(str(SPHERE))
    assert vertices.shape == (642, 3) and vertices.dtype == torch.float32
    assert faces.shape == (1280, 3) and faces.dtype == torch.int32
    v_lines = obj_lines(SPHERE, "v")
    f_lines = obj_lines(SPHERE, "f")
    assert np.allclose(vertices[0].numpy(), [float(x) for x in v_lines[0][:3]])
    assert np.allclose(vertices[-1].numpy(), [float(x) for x in v_lines[-1][:3]])
    assert faces[7].tolist() == [int(t.split("/")[0]) - 1 for t in f_lines[7]]
    assert np.allclose(np.linalg.norm(vertices.numpy(), axis=1), 1.0, atol=1e-3)


def test_load_obj_mesh_from_obj_defaults_to_white_r1_textures():
    mesh = sr.Mesh.from_obj(str(SPHERE))
    assert mesh.vertices.shape == (1, 642, 3) and mesh.textures.shape == (1, 1280, 1, 3)


def test_load_obj_spot_texture_res_2_samples_the_png_at_texel_centres():
    vertices, faces, textures = srf.load_obj(str(SPOT), load_texture=True, texture_res=2)
    assert vertices.shape == (2930, 3) and faces.shape == (5856, 3)
    assert textures.shape == (5856, 4, 3) and textures.dtype == torch.float32
    assert 0 <= float(textures.min()) and float(textures.max()) <= 1
    assert 0.2 < float(textures.mean()) < 0.95

    # A known value, computed here from the file and the PNG by hand: face 100, texel 3
    # (w_x = 1, w_y = 1, the upper triangle of cell (0, 0), centre (2/3, 2/3)/2).
    uv_table = np.array([[float(x) for x in t[:2]] for t in obj_lines(SPOT, "vt")])
    corners = obj_lines(SPOT, "f")[100]
    uv = np.array([uv_table[int(c.split("/")[1]) - 1] for c in corners])
    w = np.array([1 / 3, 1 / 3, 1 / 3])
    u, v = w @ uv
    image = _image.read_rgb(str(assets_dir() / "spot_texture.png"))[::-1]
    height, width = image.shape[:2]
    px, py = u * (width - 1), v * (height - 1)
    x0, y0 = int(px), int(py)
    fx, fy = px - x0, py - y0
    expected = (image[y0, x0] * (1 - fx) * (1 - fy) + image[y0 + 1, x0] * (1 - fx) * fy
                + image[y0, x0 + 1] * fx * (1 - fy) + image[y0 + 1, x0 + 1] * fx * fy)
    assert np.allclose(textures[100, 3].numpy(), expected, atol=1e-6)
    assert np.allclose(texel_center_barycentrics(2)[3], w)


def test_texel_centres_follow_softras_layout():
    w = texel_center_barycentrics(3)
    assert np.allclose(w[0], [1 / 9, 1 / 9, 7 / 9])  # (w_x, w_y) = (0, 0), lower triangle
    assert np.allclose(w[8], [2 / 9, 2 / 9, 5 / 9])  # (2, 2): upper triangle of cell (0, 0)
    assert np.allclose(w.sum(1), 1)
    # Each texel centre is selected back by SPEC §2's sampling rule.
    for i, (w0, w1, _) in enumerate(w):
        a, b = int(w0 * 3), int(w1 * 3)
        index = b * 3 + a if (w0 + w1) * 3 - a - b <= 1 else (2 - b) * 3 + (2 - a)
        assert index == i


def test_load_obj_normalization_fits_the_mesh_in_minus_one_one_centred():
    vertices, _ = srf.load_obj(str(SPOT), normalization=True)
    low, high = vertices.min(0)[0].numpy(), vertices.max(0)[0].numpy()
    assert np.allclose(low + high, 0, atol=1e-6)  # centred on every axis
    assert np.isclose((high - low).max(), 2, atol=1e-6)  # the longest side spans [-1, 1]
    raw, _ = srf.load_obj(str(SPOT))
    extent = (raw.max(0)[0] - raw.min(0)[0]).max()
    # A uniform scale: relative positions are kept.
    assert torch.allclose((vertices[5] - vertices[9]) * extent / 2, raw[5] - raw[9], atol=1e-6)


def test_load_obj_polygons_negative_indices_and_vertex_colours(tmp_path):
    path = tmp_path / "quad.obj"
    path.write_text("v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 1 1 1\n"
                    "f 1 2 3 4\nf -1 -2 -3\n")
    vertices, faces, colors = srf.load_obj(str(path), load_texture=True, texture_type="vertex")
    assert faces.tolist() == [[0, 1, 2], [0, 2, 3], [3, 2, 1]]
    assert colors.shape == (4, 3) and colors[3].tolist() == [1, 1, 1]
    with pytest.raises(ValueError):
        srf.load_obj(str(path), load_texture=True, texture_type="surface")  # no mtllib


def test_load_obj_missing_material_file_warns_and_gives_white(tmp_path):
    path = tmp_path / "tri.obj"
    path.write_text("mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl m\nf 1 2 3\n")
    with pytest.warns(UserWarning):
        _, _, textures = srf.load_obj(str(path), load_texture=True, texture_res=2)
    assert bool((textures == 1).all())


def test_load_obj_material_kd_colours_its_faces(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\n")
    path = tmp_path / "two.obj"
    path.write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                    "f 1 2 3\nusemtl blue\nf 1 2 3\nusemtl red\nf 1 3 2\n")
    _, _, textures = srf.load_obj(str(path), load_texture=True, texture_res=1)
    assert textures[:, 0].tolist() == [[1, 1, 1], [0, 0, 1], [1, 0, 0]]


# -- save_obj --------------------------------------------------------------------------------------

def test_save_obj_then_load_obj_round_trips_geometry(tmp_path):
    vertices, faces = srf.load_obj(str(SPHERE))
    path = tmp_path / "out.obj"
    srf.save_obj(str(path), vertices * 0.5, faces)
    again_v, again_f = srf.load_obj(str(path))
    assert torch.allclose(again_v, vertices * 0.5, atol=1e-7)
    assert torch.equal(again_f, faces)


def test_mesh_save_obj_round_trips_surface_textures_through_the_atlas(tmp_path):
    vertices, faces = srf.load_obj(str(SPHERE))
    colors = torch.from_numpy(
        np.random.RandomState(1).randint(0, 256, (faces.shape[0], 1, 3)) / 255.0).float()
    mesh = sr.Mesh(vertices, faces, textures=colors[None], texture_type="surface")
    path = tmp_path / "painted.obj"
    mesh.save_obj(str(path), save_texture=True, texture_res_out=8)
    assert (tmp_path / "painted.mtl").exists() and (tmp_path / "painted.png").exists()
    loaded = sr.Mesh.from_obj(str(path), load_texture=True, texture_res=3)
    assert torch.allclose(loaded.vertices, mesh.vertices, atol=1e-7)
    assert torch.equal(loaded.faces, mesh.faces)
    # Flat colours in 8-bit steps come back exactly at every texel.
    assert torch.allclose(loaded.textures, colors[None].expand(-1, -1, 9, -1), atol=1e-6)


def test_save_obj_vertex_colours_round_trip(tmp_path):
    vertices = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    colors = torch.tensor([[1.0, 0, 0], [0, 0.5, 0], [0, 0, 0.25]])
    path = tmp_path / "colored.obj"
    srf.save_obj(str(path), vertices, torch.tensor([[0, 1, 2]]), textures=colors,
                 texture_type="vertex")
    _, faces, loaded = srf.load_obj(str(path), load_texture=True, texture_type="vertex")
    assert torch.allclose(loaded, colors) and faces.tolist() == [[0, 1, 2]]


def test_png_writer_and_reader_round_trip(tmp_path):
    rgb = np.random.RandomState(2).randint(0, 256, (7, 5, 3)).astype(np.uint8)
    path = tmp_path / "x.png"
    _image.write_png(str(path), rgb)
    decoded = _image.read_rgb(str(path))
    assert decoded.shape == (7, 5, 3) and decoded.dtype == np.float32
    assert np.array_equal(np.round(decoded * 255).astype(np.uint8), rgb)
    grey = rgb[..., 0]
    _image.write_png(str(path), grey)
    assert np.array_equal(np.round(_image.read_rgb(str(path)) * 255).astype(np.uint8),
                          np.repeat(grey[..., None], 3, axis=2))


def test_png_reader_matches_pillow_on_spot_texture():
    # Pillow is a test dependency (the `test` extra; Debian's python3-pil in CI): a missing one
    # fails here rather than skipping the comparison.
    import PIL.Image as pil

    path = assets_dir() / "spot_texture.png"
    with pil.open(str(path)) as image:
        expected = np.asarray(image.convert("RGB"), dtype=np.float32) / 255
    assert np.array_equal(_image.read_rgb(str(path)), expected)
