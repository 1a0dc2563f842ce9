"""The Python package and the ``softvk`` command line render and differentiate the same thing:
``render_mesh`` equals ``softvk render`` (EXR) and its gradient ``softvk grad``, bit for bit;
``soft_rasterize`` on faces projected in Python agrees with them to float rounding."""

import subprocess

import numpy as np
import torch

import softvk
import softvk.torch as st

EYE = (0.5, 1.2, -2.1)
RASTER = dict(sigma_val=3e-4, gamma_val=1e-3)
FLAGS = ["--eye", ",".join(map(str, EYE)), "--sigma", "3e-4", "--gamma", "1e-3"]


def load_obj(path):
    """Vertices ``[V, 3]`` float32 and faces ``[F, 3]`` int64 of a triangle OBJ."""
    vertices, faces = [], []
    for line in open(path):
        parts = line.split()
        if parts[:1] == ["v"]:
            vertices.append([float(x) for x in parts[1:4]])
        elif parts[:1] == ["f"]:
            faces.append([int(p.split("/")[0]) - 1 for p in parts[1:4]])
    return torch.tensor(vertices, dtype=torch.float32), torch.tensor(faces, dtype=torch.int64)


def run(softvk_bin, *args):
    done = subprocess.run([str(softvk_bin), *map(str, args)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done


def test_render_mesh_equals_softvk_render_bit_for_bit(gpu, assets, softvk_bin, tmp_path):
    mesh = assets / "sphere_642.obj"
    out = tmp_path / "cli.exr"
    run(softvk_bin, "render", "--mesh", mesh, "--out", out, "--size", 32, *FLAGS)
    cli = softvk.read_exr(out)

    vertices, faces = load_obj(mesh)
    image = st.render_mesh(vertices[None], faces, eyes=torch.tensor(EYE, dtype=torch.float64), image_size=32, **RASTER)
    ours = image[0].permute(1, 2, 0).numpy()
    assert cli.shape == (32, 32, 4) and (cli[..., 3] > 0.5).sum() > 100
    np.testing.assert_array_equal(ours, cli)


def test_render_mesh_gradient_equals_softvk_grad_bit_for_bit(gpu, assets, softvk_bin, tmp_path):
    mesh = assets / "sphere_642.obj"
    weights = np.random.default_rng(1).uniform(-1, 1, (24, 24, 4)).astype(np.float32)
    softvk.write_exr(tmp_path / "w.exr", weights)
    csv, camera_csv = tmp_path / "g.csv", tmp_path / "c.csv"
    run(softvk_bin, "grad", "--mesh", mesh, "--weights", tmp_path / "w.exr", "--out", csv,
        "--camera-out", camera_csv, *FLAGS)
    cli = np.loadtxt(csv, delimiter=",", skiprows=1)[:, 1:].astype(np.float32)
    camera = dict(line.split(",") for line in camera_csv.read_text().split()[1:])
    cli_eye = np.array([float(camera[k]) for k in ("eye_x", "eye_y", "eye_z")], np.float32)

    vertices, faces = load_obj(mesh)
    vertices = vertices[None].clone().requires_grad_(True)
    eyes = torch.tensor(EYE, dtype=torch.float64, requires_grad=True)
    image = st.render_mesh(vertices, faces, eyes=eyes, image_size=24, **RASTER)
    (image * torch.from_numpy(weights).permute(2, 0, 1)[None]).sum().backward()
    assert np.abs(cli).max() > 0.1 and np.abs(cli_eye).max() > 0.01
    np.testing.assert_array_equal(vertices.grad[0].numpy(), cli)
    # The eye's gradient (look_at), as `softvk grad --camera-out` writes it.
    np.testing.assert_array_equal(eyes.grad.numpy().astype(np.float32), cli_eye)


def look_at_project(vertices, eye, viewing_angle=30.0):
    """SoftRas's look_at and perspective in float64 (SPEC §1)."""
    v = vertices.double()
    eye = torch.tensor(eye, dtype=torch.float64)
    z = -eye / eye.norm()
    x = torch.linalg.cross(torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64), z)
    x = x / x.norm()
    y = torch.linalg.cross(z, x)
    c = (v - eye) @ torch.stack([x, y, z]).T
    width = np.tan(np.radians(viewing_angle))
    return torch.stack([c[:, 0] / c[:, 2] / width, c[:, 1] / c[:, 2] / width, c[:, 2]], dim=1)


def lit_face_colors(vertices, faces):
    """SoftRas's default lighting of white faces: 0.5 ambient + 0.5 max(0, n · (0, 1, 0))."""
    v = vertices.double()[faces]
    n = torch.linalg.cross(v[:, 2] - v[:, 1], v[:, 0] - v[:, 1])
    n = n / n.norm(dim=1, keepdim=True)
    light = 0.5 + 0.5 * n[:, 1].clamp(min=0)
    return light[:, None, None].expand(-1, 1, 3)


def test_soft_rasterize_of_faces_projected_in_python_agrees_with_softvk_render(
    gpu, assets, softvk_bin, tmp_path
):
    mesh = assets / "sphere_642.obj"
    out = tmp_path / "cli.exr"
    run(softvk_bin, "render", "--mesh", mesh, "--out", out, "--size", 32, *FLAGS)
    cli = softvk.read_exr(out)

    vertices, faces = load_obj(mesh)
    screen = look_at_project(vertices, EYE).float()
    image = st.soft_rasterize(
        screen[faces][None], lit_face_colors(vertices, faces).float()[None], image_size=32, **RASTER
    )
    ours = image[0].permute(1, 2, 0).numpy()
    # The projection is rounded differently (float64 here, float32 in the engine's face set-up).
    np.testing.assert_allclose(ours, cli, atol=2e-4, rtol=0)


def test_softrenderer_on_textured_spot_equals_softvk_render_bit_for_bit(gpu, assets, softvk_bin, tmp_path):
    # The compatible module's OBJ/MTL/texture loader samples the same texels as the engine's,
    # and SoftRenderer's fast path renders what the command line renders.
    import softvk.soft_renderer as sr

    mesh_path = assets / "spot_triangulated.obj"
    out = tmp_path / "spot.exr"
    run(softvk_bin, "render", "--mesh", mesh_path, "--out", out, "--size", 48, "--texture-res", 4, *FLAGS)
    mesh = sr.Mesh.from_obj(str(mesh_path), load_texture=True, texture_res=4)
    renderer = sr.SoftRenderer(image_size=48, camera_mode="look_at", **RASTER)
    renderer.transform.set_eyes(torch.tensor([EYE], dtype=torch.float64))
    ours = renderer.render_mesh(mesh)[0].permute(1, 2, 0).detach().numpy()
    cli = softvk.read_exr(out)
    assert len(np.unique(cli[..., :3].round(2))) > 20  # textured, not flat
    np.testing.assert_array_equal(ours, cli)
