"""ti.ui 3-D scenes rendered headless: pixels checked against expectations computed here from the camera
(silhouette sizes, which side is lit, which of two surfaces is in front, covered pixel counts)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import simgrad as ti

W, H = 160, 120
FOCAL = (H / 2) / math.tan(math.radians(45) / 2)  # pixels per unit at distance 1 (fov 45 degrees)
# Taichi's particle shader sizes a sphere of radius r at distance d as a disc of r * PSCALE / d pixels, half
# the window's WIDTH over tan(fov / 2): 4/3 of the geometric silhouette r * FOCAL / d on a 4:3 window
PSCALE = (W / 2) / math.tan(math.radians(45) / 2)
BG = (1.0, 1.0, 1.0)


@pytest.fixture(autouse=True)
def _program():
    ti.init(arch=ti.cpu)


def camera(pos=(0.0, 0.0, 3.0), lookat=(0.0, 0.0, 0.0)):
    cam = ti.ui.Camera()
    cam.position(*pos)
    cam.lookat(*lookat)
    cam.up(0, 1, 0)
    return cam


def render(draw, cam=None, res=(W, H), lights=(((0.0, 0.0, 10.0), (1.0, 1.0, 1.0)),), ambient=(0.1, 0.1, 0.1)):
    """RGB float image (W, H, 3), y up, of what ``draw(scene)`` declares, over a white background."""
    window = ti.ui.Window("test", res, show_window=False)
    canvas = window.get_canvas()
    canvas.set_background_color(BG)
    scene = window.get_scene()
    scene.set_camera(cam or camera())
    scene.ambient_light(ambient)
    for pos, color in lights:
        scene.point_light(pos=pos, color=color)
    draw(scene)
    canvas.scene(scene)
    return window.get_image_buffer_as_numpy()[..., :3].copy()


def covered(img):
    return np.any(np.abs(img - np.array(BG, np.float32)) > 1e-6, axis=-1)


def uv_sphere(radius, rings=96, segments=192, center=(0.0, 0.0, 0.0)):
    t, p = np.meshgrid(np.linspace(0, np.pi, rings + 1), np.linspace(0, 2 * np.pi, segments + 1), indexing="ij")
    v = np.stack([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], -1).reshape(-1, 3)
    idx = np.arange((rings + 1) * (segments + 1)).reshape(rings + 1, segments + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    tris = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    return (v * radius + center).astype(np.float32), tris.reshape(-1).astype(np.int32)


def quad(z, half=1.0, center=(0.0, 0.0)):
    """Two triangles of a square at depth z facing +z (towards the default camera)."""
    x, y = center
    v = np.array([[x - half, y - half, z], [x + half, y - half, z], [x + half, y + half, z],
                  [x - half, y + half, z]], np.float32)
    return v, np.array([0, 1, 2, 0, 2, 3], np.int32)


def test_particle_silhouette_matches_the_projected_radius():
    r, d = 0.25, 3.0
    centers = ti.Vector.field(3, ti.f32, 1)  # a field, as GGUI programs pass them
    img = render(lambda s: s.particles(centers, radius=r, color=(1.0, 0.2, 0.2)))
    mask = covered(img)
    R = r * PSCALE / d  # the impostor's radius in pixels
    assert abs(R / (r * FOCAL / d) - W / H) < 1e-12
    assert abs(mask.sum() - math.pi * R * R) < 2 * math.pi * R  # area within one pixel ring
    ii, jj = np.nonzero(mask)
    assert abs(ii.mean() + 0.5 - W / 2) < 0.3 and abs(jj.mean() + 0.5 - H / 2) < 0.3
    width = mask[:, H // 2].sum()
    assert abs(width - 2 * R) <= 1.0
    # off the axis the distance is from the camera position, not the depth
    x, r, res = 1.5, 0.1, (400, 300)
    img = render(lambda s: s.particles(np.array([[x, 0.0, 0.0]], np.float32), radius=r, color=(1.0, 0.2, 0.2)),
                 res=res)
    R_seen = math.sqrt(covered(img).sum() / math.pi)
    pscale = (res[0] / 2) / math.tan(math.radians(45) / 2)
    assert abs(R_seen - r * pscale / math.hypot(x, d)) < 0.3  # 14.4 pixels, 16.1 by the depth


def test_mesh_sphere_silhouette_is_the_tangent_cone():
    r, d = 0.5, 3.0
    v, idx = uv_sphere(r)
    img = render(lambda s: s.mesh(v, indices=idx, color=(0.2, 0.6, 1.0)))
    mask = covered(img)
    R = r * FOCAL / math.sqrt(d * d - r * r)  # exact silhouette of a sphere seen from its axis
    assert abs(mask[:, H // 2].sum() - 2 * R) <= 1.5
    assert abs(mask[W // 2, :].sum() - 2 * R) <= 1.5
    assert abs(mask.sum() / (math.pi * R * R) - 1) < 0.03


@pytest.mark.parametrize("light_x", [5.0, -5.0])
def test_particle_is_lit_on_the_side_of_the_light(light_x):
    color = np.array([0.9, 0.6, 0.3])
    centers = np.zeros((1, 3), np.float32)
    img = render(lambda s: s.particles(centers, radius=0.8, color=tuple(color)),
                 lights=(((light_x, 0.0, 0.0), (1.0, 1.0, 1.0)),), ambient=(0.1, 0.1, 0.1))
    lum = img.sum(-1)
    R = 0.8 * FOCAL / 3.0
    cx, cy = W / 2, H / 2
    near_light = lum[int(cx + np.sign(light_x) * 0.8 * R), int(cy)]
    far_side = img[int(cx - np.sign(light_x) * 0.8 * R), int(cy)]
    assert near_light > 3 * far_side.sum()
    # facing away from the light only the ambient term is left: 0.1 * colour
    np.testing.assert_allclose(far_side, 0.1 * color, atol=1e-6)
    # the brightest pixel lies on the light's side of the centre
    i, _ = np.unravel_index(np.argmax(np.where(covered(img), lum, -1)), lum.shape)
    assert np.sign(i + 0.5 - cx) == np.sign(light_x)


def test_lambert_value_at_the_sphere_centre():
    # at the centre of a particle facing the camera, the normal is +z; a light on the axis gives full diffuse
    color = np.array([0.5, 0.4, 0.3])
    img = render(lambda s: s.particles(np.zeros((1, 3), np.float32), radius=0.5, color=tuple(color)),
                 lights=(((0.0, 0.0, 100.0), (0.5, 0.5, 0.5)),), ambient=(0.2, 0.2, 0.2))
    centre = img[W // 2 - 1: W // 2 + 1, H // 2 - 1: H // 2 + 1].reshape(-1, 3)
    np.testing.assert_allclose(centre, np.tile((0.2 + 0.5) * color, (4, 1)), atol=3e-3)


@pytest.mark.parametrize("near_first", [True, False])
def test_nearer_mesh_hides_the_farther_one_whatever_the_order(near_first):
    near_v, near_i = quad(0.5, half=0.5)
    far_v, far_i = quad(-0.5, half=1.0)
    red, blue = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)

    def draw(s):
        meshes = [(near_v, near_i, red), (far_v, far_i, blue)]
        for v, i, c in meshes if near_first else meshes[::-1]:
            s.mesh(v, indices=i, color=c)

    img = render(draw, ambient=(1.0, 1.0, 1.0), lights=())
    centre = img[W // 2, H // 2]
    np.testing.assert_allclose(centre, red, atol=1e-6)
    # outside the small near quad (projected half size 0.5 * F / 2.5) but inside the far one: blue
    edge = int(W / 2 + 0.5 * FOCAL / 2.5) + 3
    np.testing.assert_allclose(img[edge, H // 2], blue, atol=1e-6)


def test_particle_and_mesh_share_the_depth_buffer():
    # a sphere cut in half by a plane through its centre: the front half shows, the plane around it
    v, i = quad(0.0, half=2.0)
    img = render(lambda s: (s.mesh(v, indices=i, color=(0.0, 1.0, 0.0)),
                            s.particles(np.zeros((1, 3), np.float32), radius=0.5, color=(1.0, 0.0, 0.0))),
                 ambient=(1.0, 1.0, 1.0), lights=())
    np.testing.assert_allclose(img[W // 2, H // 2], (1.0, 0.0, 0.0))
    np.testing.assert_allclose(img[W // 2 + int(0.7 * FOCAL / 3), H // 2], (0.0, 1.0, 0.0))


def test_triangle_coverage_matches_pixel_centres_inside_it():
    cam = camera()
    cam.projection_mode(ti.ui.ProjectionMode.Orthogonal)  # x, y in [-1, 1] fill the image
    tri = np.array([[-0.83, -0.71, 0.0], [0.77, -0.42, 0.0], [-0.12, 0.88, 0.0]], np.float32)
    img = render(lambda s: s.mesh(tri, color=(0.0, 0.0, 0.0)), cam=cam, ambient=(0, 0, 0), lights=())
    mask = covered(img)
    # independent expectation: pixel centres inside the triangle, mapped to [-1, 1]^2
    px = (np.arange(W) + 0.5) / W * 2 - 1
    py = (np.arange(H) + 0.5) / H * 2 - 1
    X, Y = np.meshgrid(px, py, indexing="ij")

    def side(a, b):
        return (b[0] - a[0]) * (Y - a[1]) - (b[1] - a[1]) * (X - a[0])

    a, b, c = tri[:, :2].astype(np.float64)
    inside = (side(a, b) >= 0) & (side(b, c) >= 0) & (side(c, a) >= 0)
    assert abs(int((mask != inside).sum())) <= 2  # only pixel centres on an edge may differ
    e1, e2 = b - a, c - a
    area_px = 0.5 * abs(e1[0] * e2[1] - e1[1] * e2[0]) * (W / 2) * (H / 2)
    assert abs(mask.sum() - area_px) < 0.02 * area_px


def test_camera_moves_shift_the_picture_by_the_projection():
    centers = np.zeros((1, 3), np.float32)

    def centre_x(cam):
        mask = covered(render(lambda s: s.particles(centers, radius=0.3, color=(0.0, 0.0, 0.0)), cam=cam))
        return np.nonzero(mask)[0].mean() + 0.5

    x0 = centre_x(camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0)))
    x1 = centre_x(camera((0.5, 0.0, 3.0), (0.5, 0.0, 0.0)))  # camera moves right: the particle moves left
    assert abs(x0 - W / 2) < 0.3
    assert abs((x0 - x1) - 0.5 * FOCAL / 3.0) < 0.5
    # turning the camera to look at the particle from the side brings it back to the centre
    x2 = centre_x(camera((0.5, 0.0, 3.0), (0.0, 0.0, 0.0)))
    assert abs(x2 - W / 2) < 0.3


def test_camera_behind_sees_nothing_and_orthographic_particles_are_sized_as_in_taichi():
    centers = np.zeros((1, 3), np.float32)
    behind = render(lambda s: s.particles(centers, radius=0.3, color=(0, 0, 0)),
                    cam=camera((0.0, 0.0, 3.0), (0.0, 0.0, 6.0)))
    assert not covered(behind).any()
    for dist in (2.0, 5.0):
        cam = camera((0.0, 0.0, dist))
        cam.projection_mode(ti.ui.ProjectionMode.Orthogonal)
        mask = covered(render(lambda s: s.particles(centers, radius=0.5, color=(0, 0, 0)), cam=cam))
        # Taichi's shader ignores the orthographic box here: radius * PSCALE / distance, as in perspective
        assert abs(mask[:, H // 2].sum() - 2 * 0.5 * PSCALE / dist) <= 1.0


def test_two_sided_lights_a_back_face():
    v, i = quad(0.0)
    flipped = i.reshape(-1, 3)[:, ::-1].reshape(-1).copy()  # normals now point away from camera and light
    lights = (((0.0, 0.0, 5.0), (1.0, 1.0, 1.0)),)
    one = render(lambda s: s.mesh(v, indices=flipped, color=(1.0, 1.0, 1.0)), lights=lights)
    two = render(lambda s: s.mesh(v, indices=flipped, color=(1.0, 1.0, 1.0), two_sided=True), lights=lights)
    np.testing.assert_allclose(one[W // 2, H // 2], (0.1, 0.1, 0.1), atol=1e-6)  # ambient only
    assert two[W // 2, H // 2].min() > 0.99


def test_inferred_normals_equal_given_vertex_normals():
    v, idx = uv_sphere(0.6, rings=24, segments=48)
    n = v / np.linalg.norm(v, axis=1, keepdims=True)
    lights = (((2.0, 3.0, 4.0), (1.0, 1.0, 1.0)),)
    inferred = render(lambda s: s.mesh(v, indices=idx, color=(0.8, 0.8, 0.8)), lights=lights)
    given = render(lambda s: s.mesh(v, indices=idx, normals=n, color=(0.8, 0.8, 0.8)), lights=lights)
    assert np.abs(inferred - given).max() < 0.03  # averaged face normals of a fine sphere ~ radial


def test_per_vertex_color_and_index_range():
    centers = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], np.float32)
    colors = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], np.float32)
    img = render(lambda s: s.particles(centers, radius=0.2, per_vertex_color=colors, index_offset=1,
                                       index_count=2), ambient=(1.0, 1.0, 1.0), lights=())
    dx = int(FOCAL / 3)
    assert not covered(img)[W // 2 - dx, H // 2]  # particle 0 is outside the index range
    np.testing.assert_allclose(img[W // 2, H // 2], (0.0, 1.0, 0.0))
    np.testing.assert_allclose(img[W // 2 + dx, H // 2], (0.0, 0.0, 1.0))


def test_mesh_instances_are_placed_by_their_transforms():
    v, i = quad(0.0, half=0.2)
    T = np.tile(np.eye(4, dtype=np.float32), (2, 1, 1))
    T[0, 0, 3], T[1, 0, 3] = -1.0, 1.0
    transforms = ti.Matrix.field(4, 4, ti.f32, 2)
    transforms.from_numpy(T)
    img = render(lambda s: s.mesh_instance(v, indices=i, transforms=transforms, color=(0.0, 0.0, 0.0)))
    mask = covered(img)
    dx = int(FOCAL / 3)
    assert mask[W // 2 - dx, H // 2] and mask[W // 2 + dx, H // 2] and not mask[W // 2, H // 2]
    side = 0.4 * FOCAL / 3
    assert abs(mask.sum() - 2 * side * side) < 4 * 2 * side


def test_lines_cover_length_times_width():
    cam = camera()
    cam.projection_mode(ti.ui.ProjectionMode.Orthogonal)
    v = np.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]], np.float32)
    img = render(lambda s: s.lines(v, width=4, color=(0.0, 0.0, 1.0)), cam=cam)
    mask = covered(img)
    length = 0.5 * W  # 1 unit of [-1, 1] is W / 2 pixels
    assert abs(mask.sum() - length * 4) <= 2 * 4 + 8  # round caps add at most a disc
    np.testing.assert_allclose(img[W // 2, H // 2], (0.0, 0.0, 1.0))  # lines are unlit


def test_wireframe_draws_edges_only():
    v, i = quad(0.0, half=0.6)
    img = render(lambda s: s.mesh(v, indices=i, color=(0.0, 0.0, 0.0), show_wireframe=True))
    mask = covered(img)
    assert not mask[W // 2 + 10, H // 2 - 3]  # inside a triangle, off the diagonal
    assert mask[W // 2, H // 2]  # on the shared diagonal
    assert mask[int(W / 2 + 0.6 * FOCAL / 3), H // 2]  # on the right edge (1 pixel wide)
    assert not mask[int(W / 2 + 0.6 * FOCAL / 3) - 2, H // 2]


def test_scene_is_drawn_over_the_canvas_and_emptied_after_render():
    window = ti.ui.Window("t", (W, H), show_window=False)
    canvas, scene = window.get_canvas(), window.get_scene()
    canvas.set_background_color((0.0, 1.0, 0.0))
    scene.set_camera(camera())
    scene.particles(np.zeros((1, 3), np.float32), radius=0.3, color=(1.0, 0.0, 0.0))
    canvas.scene(scene)
    img = window.get_image_buffer_as_numpy()
    assert img.shape == (W, H, 4)
    np.testing.assert_allclose(img[0, 0, :3], (0.0, 1.0, 0.0))
    assert img[W // 2, H // 2, 0] > 0 and img[W // 2, H // 2, 1] == 0
    window.show()
    canvas.set_background_color((0.0, 1.0, 0.0))
    canvas.scene(scene)  # nothing declared since the last render
    np.testing.assert_allclose(window.get_image_buffer_as_numpy()[W // 2, H // 2, :3], (0.0, 1.0, 0.0))


def test_renderer_survives_a_new_program():
    centers = np.array([[0.1, -0.2, 0.3]], np.float32)
    first = render(lambda s: s.particles(centers, radius=0.4, color=(0.3, 0.5, 0.7)))
    ti.init(arch=ti.cpu)
    x = ti.field(ti.f32, 8)  # the user's own fields after the new init are untouched
    x.fill(2.0)
    second = render(lambda s: s.particles(centers, radius=0.4, color=(0.3, 0.5, 0.7)))
    np.testing.assert_array_equal(first, second)
    assert (x.to_numpy() == 2.0).all()


def test_camera_matrices_follow_glm():
    cam = camera((1.0, 2.0, 3.0), (0.0, 0.0, 0.0))
    view = cam.get_view_matrix()
    p = view @ np.array([0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(p[:3], (0.0, 0.0, -math.sqrt(14)), atol=1e-12)  # lookat is straight ahead
    np.testing.assert_allclose(view[:3, :3] @ view[:3, :3].T, np.eye(3), atol=1e-12)
    proj = cam.get_projection_matrix(4 / 3)
    clip = proj @ np.array([0.0, 1.0, -1.0, 1.0])
    assert abs(clip[1] / clip[3] - 1 / math.tan(math.radians(22.5))) < 1e-12


def test_bad_inputs_raise_located_errors():
    window = ti.ui.Window("t", (W, H), show_window=False)
    scene = window.get_scene()
    with pytest.raises(ti.SimgradTypeError, match=r"scene.particles: centers must be .*3-vectors.*\(5, 2\)") as e:
        scene.particles(np.zeros((5, 2), np.float32), radius=0.1)
    assert "test_ggui_scene.py" in str(e.value)
    with pytest.raises(ti.SimgradTypeError, match="indices must lie in"):
        scene.mesh(np.zeros((3, 3), np.float32), indices=np.array([0, 1, 3], np.int32))
    with pytest.raises(ti.SimgradTypeError, match="indices must be integers"):
        scene.mesh(np.zeros((3, 3), np.float32), indices=np.array([0.0, 1.0, 2.0]))
    with pytest.raises(ti.SimgradTypeError, match="per_vertex_color has 2 colours for 3 centers"):
        scene.particles(np.zeros((3, 3), np.float32), radius=0.1, per_vertex_color=np.zeros((2, 3)))
    with pytest.raises(ti.SimgradTypeError, match="index range"):
        scene.particles(np.zeros((3, 3), np.float32), radius=0.1, index_offset=2, index_count=5)
    with pytest.raises(ti.SimgradTypeError, match="must hold numbers"):
        scene.particles(np.array([["a", "b", "c"]]), radius=0.1)
    with pytest.raises(ti.SimgradTypeError, match="4x4 matrices"):
        scene.mesh_instance(np.zeros((3, 3), np.float32), transforms=np.zeros((2, 3, 3)))


def test_declared_arrays_are_snapshots():
    # what a scene draws is what the arrays held when declared, as Taichi copies them into its buffers
    window = ti.ui.Window("t", (W, H), show_window=False)
    canvas, scene = window.get_canvas(), window.get_scene()
    scene.set_camera(camera())
    centers = np.zeros((1, 3), np.float32)
    scene.particles(centers, radius=0.3, color=(1.0, 0.0, 0.0))
    centers[0, 0] = 5.0  # moved out of view after the declaration
    canvas.scene(scene)
    assert window.get_image_buffer_as_numpy()[W // 2, H // 2, 0] > 0


def test_floor_running_behind_the_camera_is_clipped_not_dropped():
    # two big triangles of a floor at y = -1 reaching far behind the camera (at z = 3): the floor must fill
    # the lower part of the picture up to its bottom edge; which rows it covers follows from the camera
    v = np.array([[-50, -1, -50], [50, -1, -50], [50, -1, 50], [-50, -1, 50]], np.float32)
    i = np.array([0, 2, 1, 0, 3, 2], np.int32)  # facing up
    img = render(lambda s: s.mesh(v, indices=i, color=(0.0, 0.0, 0.0)), lights=())
    mask = covered(img)
    column = mask[W // 2]
    # a row is floor when its ray goes down steeply enough to hit y = -1 within 53 units (the far edge)
    slope = -((np.arange(H) + 0.5) - H / 2) / FOCAL  # downward slope of each row's ray
    expected = slope * 53 > 1
    assert (column != expected).sum() <= 1
    assert column[0] and column[: H // 2 - 4].all()  # down to the bottom row, though vertices are behind
    # each triangle had a vertex behind the camera and was split: the picture is still seamless
    assert mask[:, : H // 2 - 4].all()


def test_non_finite_geometry_draws_nothing_and_does_not_stall():
    bad = np.array([[np.nan, 0, 0], [0, np.inf, 0], [1e30, 1e30, 1], [0, 0, np.nan]], np.float32)
    v = np.array([[0, 0, 0], [np.nan, 0, 0], [0, 1, 0], [1e30, 0, 0], [0, 1e30, 0], [0, 0, -1e30]], np.float32)
    img = render(lambda s: (s.particles(np.repeat(bad, 2000, axis=0), radius=0.1),
                            s.mesh(v, indices=np.array([0, 1, 2], np.int32)),
                            s.lines(v[:2], width=3)))
    assert not covered(img).any()
    # an infinite radius covers the whole picture at the depth of the camera (finite colours)
    img = render(lambda s: s.particles(np.zeros((1, 3), np.float32), radius=np.inf, color=(0.0, 0.0, 0.0)))
    assert covered(img).all() and np.isfinite(img).all()


def reversed_z(d, near=0.1, far=1000.0, ortho=False):
    """Taichi's depth buffer value for camera depth d: glm's zero-to-one projection with near and far swapped."""
    return (far - d) / (far - near) if ortho else near * (far - d) / (d * (far - near))


def test_depth_buffer_is_taichis_reversed_z():
    window = ti.ui.Window("test", (W, H), show_window=False)
    assert not window.get_depth_buffer_as_numpy().any()  # nothing drawn yet
    canvas, scene = window.get_canvas(), window.get_scene()
    scene.set_camera(camera())
    v, i = quad(-1.0, half=0.6)
    scene.mesh(v, indices=i, color=(0.5, 0.5, 0.5))
    scene.particles(np.array([[0.0, 0.0, 0.0]], np.float32), radius=0.25, color=(1.0, 0.0, 0.0))
    canvas.scene(scene)
    depth = window.get_depth_buffer_as_numpy()
    assert depth.dtype == np.float32 and depth.shape == (W, H)
    assert depth[0, 0] == 0.0  # background: cleared to the far end
    # the sphere's front surface at the centre is 3 - 0.25 from the camera; the quad behind it at depth 4
    np.testing.assert_allclose(depth[W // 2, H // 2], reversed_z(2.75), rtol=1e-3)
    np.testing.assert_allclose(depth[W // 2 + 19, H // 2], reversed_z(4.0), rtol=1e-5)  # quad 21.7 px, disc 16
    field = ti.field(ti.f32, (W, H))
    window.get_depth_buffer(field)
    np.testing.assert_array_equal(field.to_numpy(), depth)
    with pytest.raises(ValueError):
        window.get_depth_buffer(ti.field(ti.f32, (W, H + 1)))
    cam = camera()
    cam.projection_mode(ti.ui.ProjectionMode.Orthogonal)
    scene.set_camera(cam)
    scene.mesh(v, indices=i, color=(0.5, 0.5, 0.5))
    canvas.scene(scene)
    np.testing.assert_allclose(window.get_depth_buffer_as_numpy()[W // 2, H // 2], reversed_z(4.0, ortho=True),
                               rtol=1e-6)


def test_scene_made_directly_is_deprecated_as_in_taichi():
    with pytest.warns(DeprecationWarning, match=r"Instantiating ti.ui.Scene directly is deprecated, use the "
                                                r"get_scene\(\) function from a taichi.ui.Window object instead."):
        scene = ti.ui.Scene()
    scene.particles(np.zeros((1, 3), np.float32), radius=0.5)  # and still works
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ti.ui.Window("w", (8, 8), show_window=False).get_scene()
