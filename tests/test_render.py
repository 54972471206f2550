"""Offscreen renderer: framing, invariance, orientation, depth, two-sided lighting, PNG output."""
import numpy as np
import pytest
import trimesh
from PIL import Image

from retarget.render import (Renderer, contact_sheet, heatmap_colors, render_frontal, save_png,
                             view_rotation)

SIZE = 64


@pytest.fixture(scope="module")
def renderer():
    return Renderer(SIZE)


@pytest.fixture(scope="module")
def blob():
    """An egg (taller than wide) with a bump on the character's left (+x) side."""
    s = trimesh.creation.icosphere(subdivisions=3)
    v = s.vertices * np.array([1.0, 1.3, 0.9])
    v[:, 0] += 0.5 * np.exp(-((v[:, 1] ** 2 + v[:, 2] ** 2) / 0.1)) * (v[:, 0] > 0)
    return v, np.asarray(s.faces)


def mask(img):
    return img.max(axis=-1) > 0


def test_image_is_nonempty_centred_and_framed(renderer, blob):
    v, f = blob
    img = renderer.render(v, f)
    assert img.shape == (SIZE, SIZE, 3) and img.dtype == np.float32
    assert 0.0 <= img.min() and img.max() <= 1.0
    m = mask(img)
    rows, cols = np.nonzero(m)
    # the taller axis (y) spans the image minus the fixed margin, centred
    assert abs((rows.max() - rows.min() + 1) - 0.95 * SIZE) <= 2
    assert abs(0.5 * (rows.min() + rows.max()) - (SIZE - 1) / 2) <= 1
    assert abs(0.5 * (cols.min() + cols.max()) - (SIZE - 1) / 2) <= 1
    assert 0.3 < m.mean() < 0.9


@pytest.mark.parametrize("mode", ["shaded", "normals", "depth"])
def test_invariant_to_scale_and_translation(renderer, blob, mode):
    v, f = blob
    a = renderer.render(v, f, mode=mode)
    b = renderer.render(v * 37.0 + np.array([5.0, -300.0, 120.0]), f, mode=mode)
    assert np.abs(a - b).mean() < 2e-3
    assert (np.abs(a - b) > 0.1).mean() < 0.005  # at most a few edge pixels differ


def test_front_view_shows_character_left_on_image_right(renderer, blob):
    v, f = blob
    colors = np.where(v[:, :1] > 0, [[1.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]])
    img = renderer.render(v, f, mode="colors", vertex_colors=colors)
    red_cols = np.nonzero(img[..., 0] > img[..., 2] + 0.1)[1]
    blue_cols = np.nonzero(img[..., 2] > img[..., 0] + 0.1)[1]
    assert red_cols.mean() > SIZE / 2 > blue_cols.mean()
    # the bump on +x (at mid height) puts the egg's axis x = 0 left of the image centre
    row = img[SIZE // 2]
    axis = np.nonzero(row[:, 2] > row[:, 0])[0].max()
    assert axis < SIZE / 2 - 4


def test_side_view_faces_the_left_side(renderer, blob):
    v, f = blob
    colors = np.where(v[:, :1] > 0, [[1.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]])
    img = renderer.render(v, f, mode="colors", vertex_colors=colors, view="side")
    m = mask(img)
    assert (img[..., 0] > img[..., 2])[m].mean() > 0.95
    assert np.allclose(view_rotation("side") @ [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    tq = renderer.render(v, f, mode="colors", vertex_colors=colors, view="three_quarter")
    share = (tq[..., 0] > tq[..., 2])[mask(tq)].mean()
    assert 0.55 < share < 0.95


def test_depth_near_is_bright_and_occludes():
    """Two overlapping quads: the nearer (larger z) one wins whatever the draw order."""
    r = Renderer(32)
    quad = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    near, far = quad + [0, 0, 1.0], quad * [0.5, 0.5, 1]
    for first, second in ((near, far), (far, near)):
        v = np.vstack([first, second])
        f = np.vstack([faces, faces + 4])
        colors = np.where((v[:, 2] > 0.5)[:, None], [[1.0, 0, 0]], [[0, 0, 1.0]])
        img = r.render(v, f, mode="colors", vertex_colors=colors)
        assert img[16, 16, 0] > 0.2 and img[16, 16, 2] == 0.0
    depth = r.render(np.vstack([near, far]), np.vstack([faces, faces + 4]), mode="depth")
    assert depth.shape == (32, 32, 1)
    assert depth[16, 16, 0] > 0.9  # nearest surface close to 1


def test_two_sided_lighting_ignores_winding(renderer, blob):
    v, f = blob
    a = renderer.render(v, f, mode="shaded")
    b = renderer.render(v, f[:, ::-1], mode="shaded")
    assert np.abs(a - b).max() < 1e-4
    # the headlight makes the centre (facing the camera) brighter than the rim
    m = mask(a)
    assert a[SIZE // 2, SIZE // 2 - 8, 0] > np.percentile(a[m][:, 0], 10) + 0.2


def test_fit_box_matches_own_bounds(renderer, blob):
    v, f = blob
    box = np.stack([v.min(axis=0), v.max(axis=0)])
    assert np.array_equal(renderer.render(v, f, fit=box), renderer.render(v, f))
    # framing a larger box shrinks the silhouette
    big = renderer.render(v, f, fit=box * 2.0)
    assert mask(big).sum() < 0.5 * mask(renderer.render(v, f)).sum()


def test_render_frontal_channels(blob):
    v, f = blob
    x = render_frontal(v, f, 48)
    assert x.shape == (2, 48, 48) and x.dtype == np.float32
    assert (x[1] > 0).sum() == (x[0] > 0).sum()  # same silhouette in both channels
    y = render_frontal(v * 0.01, f, 48, channels=("normals", "depth", "shaded"))
    assert y.shape == (5, 48, 48)
    assert np.abs(y[4] - x[0]).mean() < 2e-3 and np.abs(y[3] - x[1]).mean() < 2e-3


def test_render_modes_equals_one_render_per_mode(renderer, blob):
    v, f = blob
    modes = ("shaded", "depth", "normals", "shaded")
    for img, mode in zip(renderer.render_modes(v, f, modes, view="three_quarter"), modes):
        np.testing.assert_array_equal(img, renderer.render(v, f, mode=mode, view="three_quarter"))
    x = render_frontal(v, f, 48, channels=("shaded", "depth"))
    np.testing.assert_array_equal(x[1], render_frontal(v, f, 48, channels=("depth",))[0])
    np.testing.assert_array_equal(x[0], render_frontal(v, f, 48, channels=("shaded",))[0])


@pytest.mark.parametrize("modes", [("shaded", "depth"), ("depth", "shaded"), ("depth", "depth")])
def test_shaded_and_depth_in_one_pass_equal_their_own_renders(renderer, blob, modes):
    v, f = blob
    images = renderer.render_modes(v, f, modes)
    assert len(images) == len(modes)
    for img, mode in zip(images, modes):
        assert img.shape == (SIZE, SIZE, 1 if mode == "depth" else 3)
        np.testing.assert_array_equal(img, renderer.render(v, f, mode=mode))


def test_unknown_mode_and_missing_colors(renderer, blob):
    v, f = blob
    with pytest.raises(ValueError):
        renderer.render(v, f, mode="xray")
    with pytest.raises(ValueError):
        renderer.render(v, f, mode="colors")
    with pytest.raises(ValueError):
        renderer.render(v, f, view="top")


def test_heatmap_colors_fixed_scale():
    c = heatmap_colors(np.array([0.0, 1.0, 2.0, 4.0, 8.0]), vmax=4.0)
    assert c.shape == (5, 3) and c.dtype == np.float32
    assert np.allclose(c[3], c[4])  # saturates above vmax
    lum = c.sum(axis=1)
    assert lum[0] > lum[1] > lum[2] > lum[3]  # YlOrRd darkens with the error
    assert c[0, 0] > 0.9 and c[0, 1] > 0.9  # light yellow at 0


def test_save_png_and_contact_sheet(tmp_path, renderer, blob):
    v, f = blob
    imgs = [renderer.render(v, f, mode=m) for m in ("shaded", "normals", "depth")]
    sheet = contact_sheet(imgs, ["shaded", "normals", "depth"], cols=2, label_height=12)
    assert sheet.shape == (2 * (SIZE + 12), 2 * SIZE, 3)
    strip = sheet[SIZE:SIZE + 12, :SIZE]
    assert (strip < 0.5).any()  # the label was drawn
    assert np.allclose(sheet[:SIZE, SIZE:, :], imgs[1], atol=1 / 255)
    out = tmp_path / "sub" / "sheet.png"
    save_png(out, sheet)
    back = np.asarray(Image.open(out), dtype=np.float32) / 255
    assert back.shape == sheet.shape and np.abs(back - sheet).max() <= 1 / 255 + 1e-6
    assert sorted(p.name for p in out.parent.iterdir()) == ["sheet.png"]  # no temp file left


def test_fit_false_takes_normalised_device_coordinates(renderer, blob):
    v, f = blob
    half = v / np.abs(v[:, 1]).max() * 0.5  # y spans [-0.5, 0.5]: half the image height
    rows, cols = np.nonzero(mask(renderer.render(half, f, fit=False)))
    assert abs((rows.max() - rows.min() + 1) - SIZE / 2) <= 2


def _render_in_child(_):
    try:
        render_frontal(np.eye(3), [[0, 1, 2]], 16)
        return "rendered"
    except RuntimeError as e:
        return str(e)


def test_forked_worker_gets_a_clear_error_instead_of_hanging(renderer):
    import multiprocessing as mp

    with mp.get_context("fork").Pool(1) as pool:
        msg = pool.map_async(_render_in_child, [0]).get(timeout=60)[0]
    assert "spawn" in msg
