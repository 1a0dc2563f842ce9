"""softvk.soft_renderer's cameras and lights against SPEC §1/§2 formulas computed here in numpy.

None of these tests needs the renderer.
"""

import math

import numpy as np
import pytest
import torch

import softvk.soft_renderer as sr
import softvk.soft_renderer.functional as srf


def _normalize(v):
    return v / np.linalg.norm(v)


def spec_look_at(points, eye, at=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0)):
    """SPEC §1: z = normalize(at - eye), x = normalize(cross(up, z)), y = cross(z, x);
    p_c = R (p - eye) with rows x, y, z."""
    eye, at, up = (np.asarray(a, dtype=np.float64) for a in (eye, at, up))
    z = _normalize(at - eye)
    x = _normalize(np.cross(up, z))
    y = np.cross(z, x)
    return (np.asarray(points, dtype=np.float64) - eye) @ np.stack([x, y, z]).T


def spec_eye(d, el, az):
    el, az = math.radians(el), math.radians(az)
    return np.array([d * math.cos(el) * math.sin(az), d * math.sin(el),
                     -d * math.cos(el) * math.cos(az)])


POINTS = np.array([[0.1, -0.2, 0.3], [-0.4, 0.5, 0.0], [0.25, 0.25, -0.6], [0.0, 0.0, 0.0]])


@pytest.mark.parametrize("d, el, az", [(2.732, 0, 0), (2.732, 30, 0), (2.0, 30, 45),
                                       (3.5, -20, 200), (1.5, 80, -135)])
def test_get_points_from_angles_matches_spec_formula_for_numbers_and_tensors(d, el, az):
    expected = spec_eye(d, el, az)
    assert np.allclose(srf.get_points_from_angles(d, el, az), expected, atol=1e-12)

    eyes = srf.get_points_from_angles(torch.tensor([d, d], dtype=torch.float64),
                                      torch.tensor([el, 0.0], dtype=torch.float64),
                                      torch.tensor([az, 0.0], dtype=torch.float64))
    assert eyes.shape == (2, 3) and eyes.dtype == torch.float64
    assert np.allclose(eyes[0].numpy(), expected, atol=1e-12)
    assert np.allclose(eyes[1].numpy(), [0, 0, -d], atol=1e-12)


def test_get_points_from_angles_radians_and_float32_default():
    assert np.allclose(srf.get_points_from_angles(2.0, math.pi / 6, math.pi / 4, degrees=False),
                       spec_eye(2.0, 30, 45), atol=1e-12)
    eyes = srf.get_points_from_angles(torch.ones(3) * 2.732, torch.ones(3) * 30.0,
                                      -torch.arange(3).float() * 15)
    assert eyes.dtype == torch.float32 and eyes.shape == (3, 3)
    assert np.allclose(eyes[2].numpy(), spec_eye(2.732, 30, -30), atol=1e-6)


def test_look_at_default_eye_is_a_translation():
    vertices = torch.tensor(POINTS[None], dtype=torch.float64)
    out = srf.look_at(vertices, [0, 0, -2.732])
    assert np.allclose(out[0].numpy(), POINTS + [0, 0, 2.732], atol=1e-12)


@pytest.mark.parametrize("d, el, az", [(2.732, 30, 0), (2.0, 30, 45), (3.5, -20, 200)])
def test_look_at_matches_spec_formula(d, el, az):
    eye = spec_eye(d, el, az)
    vertices = torch.tensor(POINTS[None], dtype=torch.float64)
    out = srf.look_at(vertices, eye)
    assert out.dtype == torch.float64
    assert np.allclose(out[0].numpy(), spec_look_at(POINTS, eye), atol=1e-10)
    # The eye is at depth 0 and the origin at depth d.
    assert np.isclose(out[0, 3, 2].item(), d, atol=1e-10)
    assert np.allclose(out[0, 3, :2].numpy(), 0, atol=1e-10)


def test_look_at_float32_and_one_eye_per_mesh():
    eyes = np.stack([spec_eye(2.732, 30, 0), spec_eye(2.0, 10, 90)])
    vertices = torch.tensor(np.stack([POINTS, POINTS]), dtype=torch.float32)
    out = srf.look_at(vertices, torch.tensor(eyes))  # float64 eyes follow the float32 vertices
    assert out.dtype == torch.float32
    for b in range(2):
        assert np.allclose(out[b].numpy(), spec_look_at(POINTS, eyes[b]), atol=1e-5)


def test_look_along_z_is_look_at_the_origin_from_minus_z():
    vertices = torch.tensor(POINTS[None], dtype=torch.float64)
    eye = [0.3, -0.2, -2.5]
    out = srf.look(vertices, eye, [0, 0, 1])
    assert np.allclose(out[0].numpy(), spec_look_at(POINTS, eye, at=np.add(eye, [0, 0, 1])),
                       atol=1e-10)
    direction = _normalize(np.array([1.0, -0.5, 2.0]))
    out = srf.look(vertices, eye, direction)
    assert np.allclose(out[0].numpy(), spec_look_at(POINTS, eye, at=np.add(eye, direction)),
                       atol=1e-10)


@pytest.mark.parametrize("angle", [30, 15, 45])
def test_perspective_matches_spec_formula(angle):
    camera = spec_look_at(POINTS, spec_eye(2.732, 30, 20))
    out = srf.perspective(torch.tensor(camera[None]), angle=angle)[0].numpy()
    t = math.tan(math.radians(angle))
    assert np.allclose(out[:, 0], camera[:, 0] / (camera[:, 2] * t), atol=1e-12)
    assert np.allclose(out[:, 1], camera[:, 1] / (camera[:, 2] * t), atol=1e-12)
    assert np.allclose(out[:, 2], camera[:, 2], atol=1e-12)


def test_orthogonal_scales_x_and_y_only():
    out = srf.orthogonal(torch.tensor(POINTS[None]), scale=0.7)[0].numpy()
    assert np.allclose(out, POINTS * [0.7, 0.7, 1.0])


def test_projection_matches_pinhole_and_brown_distortion_by_hand():
    P = np.array([[500.0, 0.0, 256.0, 10.0], [0.0, 480.0, 250.0, -5.0], [0.0, 0.0, 1.0, 3.0]])
    coeffs = np.array([0.1, -0.05, 0.002, -0.003, 0.01])
    orig_size = 512
    out = srf.projection(torch.tensor(POINTS[None]), torch.tensor(P[None]),
                         torch.tensor(coeffs[None]), orig_size)[0].numpy()
    k1, k2, p1, p2, k3 = coeffs
    for p, o in zip(POINTS, out):
        x, y, z = P @ np.append(p, 1.0)
        xp, yp = x / (z + 1e-5), y / (z + 1e-5)
        r2 = xp * xp + yp * yp
        radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
        xd = xp * radial + 2 * p1 * xp * yp + p2 * (r2 + 2 * xp * xp)
        yd = yp * radial + p1 * (r2 + 2 * yp * yp) + 2 * p2 * xp * yp
        expected = [2 * (xd - orig_size / 2) / orig_size, 2 * (yd - orig_size / 2) / orig_size, z]
        assert np.allclose(o, expected, rtol=1e-10, atol=1e-10)


def test_projection_without_distortion_is_the_pinhole_camera():
    P = np.array([[[300.0, 0.0, 200.0, 0.0], [0.0, 300.0, 200.0, 0.0], [0.0, 0.0, 1.0, 2.0]]])
    transform = sr.Transform("projection", P=P, orig_size=400)
    mesh = sr.Mesh(torch.tensor(POINTS, dtype=torch.float32), torch.tensor([[0, 1, 2]]))
    out = transform(mesh).vertices[0].numpy()
    h = np.c_[POINTS, np.ones(len(POINTS))] @ P[0].T
    expected_x = 2 * (h[:, 0] / (h[:, 2] + 1e-5) - 200) / 400
    assert np.allclose(out[:, 0], expected_x, atol=1e-5)
    assert np.allclose(out[:, 2], h[:, 2], atol=1e-5)


def test_transform_projection_mode_requires_a_matrix():
    with pytest.raises(ValueError):
        sr.Transform("projection")
    with pytest.raises(ValueError):
        sr.Transform("orbit")


def test_transform_look_at_default_eye_and_set_eyes_from_angles():
    transform = sr.Transform("look_at")
    assert np.allclose(transform.eyes, [0, 0, -(1 / math.tan(math.radians(30)) + 1)])
    transform.set_eyes_from_angles(2.0, 30, 45)
    assert np.allclose(transform.eyes, spec_eye(2.0, 30, 45))
    mesh = sr.Mesh(torch.tensor(POINTS, dtype=torch.float64), torch.tensor([[0, 1, 2]]))
    out = transform(mesh).vertices[0].numpy()
    camera = spec_look_at(POINTS, spec_eye(2.0, 30, 45))
    t = math.tan(math.radians(30))
    assert np.allclose(out, np.c_[camera[:, :2] / (camera[:, 2:] * t), camera[:, 2]], atol=1e-10)

    transform.set_eyes(torch.zeros(4, 3))
    assert transform.eyes.shape == (4, 3)
    with pytest.raises(ValueError):
        sr.Transform("projection", P=np.zeros((1, 3, 4))).set_eyes([0, 0, -1])


def test_transform_orthographic_look_mode():
    transform = sr.Transform("look", perspective=False, viewing_scale=0.5, eye=[0, 0, -3],
                             camera_direction=[0, 0, 1])
    mesh = sr.Mesh(torch.tensor(POINTS, dtype=torch.float64), torch.tensor([[0, 1, 2]]))
    out = transform(mesh).vertices[0].numpy()
    assert np.allclose(out, np.c_[POINTS[:, :2] * 0.5, POINTS[:, 2] + 3], atol=1e-12)


def test_lighting_functions_add_ambient_and_clamped_directional_light():
    normals = torch.tensor([[[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.6, 0.8, 0.0]]])
    light = torch.zeros(1, 3, 3)
    light = srf.ambient_lighting(light, 0.4, [1.0, 0.5, 0.25])
    light = srf.directional_lighting(light, normals, 0.5, (1, 1, 1), (0, 1, 0))
    expected = np.array([0.4, 0.2, 0.1]) + 0.5 * np.array([[1.0], [0.0], [0.8]])
    assert np.allclose(light[0].numpy(), expected, atol=1e-6)


def test_lighting_module_multiplies_surface_textures_by_face_light():
    # One face in the x-z plane wound so that its SPEC normal is +y, one facing +z.
    vertices = torch.tensor([[0.0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0]])
    faces = torch.tensor([[0, 1, 2], [0, 3, 2]])
    mesh = sr.Mesh(vertices, faces, textures=torch.full((2, 4, 3), 0.5), texture_type="surface")
    normals = mesh.surface_normals[0].numpy()
    assert np.allclose(normals[0], [0, 1, 0]) and np.allclose(np.abs(normals[1]), [0, 0, 1])
    lit = sr.Lighting()(mesh)  # ambient 0.5 + 0.5 max(0, n . +y)
    assert np.allclose(lit.textures[0, 0].numpy(), 0.5 * 1.0)
    assert np.allclose(lit.textures[0, 1].numpy(), 0.5 * 0.5)


def test_lighting_module_vertex_mode_uses_vertex_normals():
    vertices = torch.tensor([[0.0, 0, 0], [0, 0, 1], [1, 0, 0]])
    mesh = sr.Mesh(vertices, torch.tensor([[0, 1, 2]]), texture_type="vertex")
    lit = sr.Lighting("vertex", 0.25, [1, 1, 1], 0.5, [1, 0, 0], [0, 1, 0])(mesh)
    assert np.allclose(lit.textures[0].numpy(), [[0.75, 0.25, 0.25]] * 3, atol=1e-6)
    with pytest.raises(ValueError):
        sr.Lighting("pixel")
