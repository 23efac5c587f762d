"""Tests of the gray-level images (fesdic_core.imaging.image): spline interpolant, gradient, pyramids, I/O."""
import cv2
import numpy as np
import pytest
from scipy import ndimage

from fesdic_core import parallel
from fesdic_core.cameras.camera import Camera
from fesdic_core.imaging import bspline3, image as image_module
from fesdic_core.imaging.image import DEFAULT_PREFILTER_PX, Image, ImageError, pyramid, read_image


def _random_image(shape=(37, 53), seed=0, prefilter_px=0.0):
    """A white-noise image; by default with the bare cubic B-spline (no prefilter)."""
    return Image.from_array(np.random.default_rng(seed).uniform(0.0, 255.0, size=shape), "random",
                            prefilter_px=prefilter_px)


def _random_points(image, n, seed, pad=0.0):
    h, w = image.shape
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-0.5 - pad, w - 0.5 + pad, n),
                            rng.uniform(-0.5 - pad, h - 0.5 + pad, n)])


def test_interpolant_reproduces_pixel_values():
    """Without prefilter the model is the cubic B-spline THROUGH the pixel values."""
    image = _random_image()
    h, w = image.shape
    yy, xx = np.mgrid[0:h, 0:w]
    xy = np.column_stack([xx.ravel(), yy.ravel()]).astype(float)
    np.testing.assert_allclose(image.evaluate(xy), image.values.ravel(), rtol=0, atol=1e-9)
    value, _ = image.evaluate_with_gradient(xy)
    np.testing.assert_allclose(value, image.values.ravel(), rtol=0, atol=1e-9)


@pytest.mark.parametrize("prefilter_px", [0.0, 0.8])
@pytest.mark.parametrize("shape", [(37, 53), (2, 9), (1, 6)])
def test_value_and_gradient_are_the_same_spline_everywhere(shape, prefilter_px):
    """evaluate_with_gradient and evaluate (the value-only pass) agree with scipy's
    map_coordinates, also on and beyond the border."""
    image = _random_image(shape, seed=1, prefilter_px=prefilter_px)
    xy = _random_points(image, 4000, seed=2, pad=20.0)
    value, grad = image.evaluate_with_gradient(xy)
    scipy_value = ndimage.map_coordinates(image.coefficients, [xy[:, 1], xy[:, 0]], order=3,
                                          mode="mirror", prefilter=False)
    np.testing.assert_allclose(value, scipy_value, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(image.evaluate(xy), value)
    np.testing.assert_array_equal(grad, image.gradient(xy))
    h = 1e-5
    scale = np.abs(grad).max() if np.abs(grad).max() > 0 else 1.0
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        fd = (image.evaluate(xy + e) - image.evaluate(xy - e)) / (2 * h)
        assert np.abs(grad[:, k] - fd).max() / scale < 1e-6


def test_gradient_of_smooth_image_matches_analytic_derivative():
    h, w = 80, 100
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    kx, ky = 2 * np.pi / 23.0, 2 * np.pi / 31.0
    image = Image.from_array(100.0 + 50.0 * np.sin(kx * xx) * np.cos(ky * yy), prefilter_px=0.0)
    xy = _random_points(image, 2000, seed=3)
    xy = xy[image.inside(xy, margin=8.0)]                          # away from the mirror border
    x, y = xy[:, 0], xy[:, 1]
    value, grad = image.evaluate_with_gradient(xy)
    exact = 100.0 + 50.0 * np.sin(kx * x) * np.cos(ky * y)
    gx = 50.0 * kx * np.cos(kx * x) * np.cos(ky * y)
    gy = -50.0 * ky * np.sin(kx * x) * np.sin(ky * y)
    # cubic spline interpolation error O((k h)^4): about 1e-3 relative at 23 px per period
    assert np.abs(value - exact).max() < 1e-3 * 50.0
    assert np.abs(grad[:, 0] - gx).max() < 1e-2 * 50.0 * kx
    assert np.abs(grad[:, 1] - gy).max() < 1e-2 * 50.0 * ky


def test_nan_coordinates_give_nan():
    image = _random_image()
    value, grad = image.evaluate_with_gradient(np.array([[np.nan, 3.0], [4.0, 5.0]]))
    assert np.isnan(value[0]) and np.isnan(grad[0]).all()
    assert np.isfinite(value[1]) and np.isfinite(grad[1]).all()


def test_inside():
    image = _random_image((20, 30))
    xy = np.array([[1.0, 1.0], [0.99, 5.0], [28.0, 18.0], [28.01, 5.0], [5.0, 18.01], [np.nan, 5.0]])
    np.testing.assert_array_equal(image.inside(xy), [True, False, True, False, False, False])
    assert image.inside(np.array([[-0.5, -0.5]]), margin=0.0).all()


@pytest.mark.parametrize("prefilter_px", [0.0, 0.9])
@pytest.mark.parametrize("shape", [(8, 10), (9, 11)])
def test_coarsen_is_block_mean(shape, prefilter_px):
    """The coarse RAW values are the block means of the raw (not of the prefiltered) values."""
    a = np.random.default_rng(4).uniform(0, 1000, size=shape)
    coarse = Image.from_array(a, prefilter_px=prefilter_px).coarsen()
    h, w = shape[0] // 2, shape[1] // 2
    assert coarse.shape == (h, w)
    i, j = np.random.default_rng(5).integers(0, [h, w], size=(20, 2)).T
    expected = (a[2 * i, 2 * j] + a[2 * i + 1, 2 * j] + a[2 * i, 2 * j + 1] + a[2 * i + 1, 2 * j + 1]) / 4
    np.testing.assert_allclose(coarse.values[i, j], expected, rtol=1e-14)
    assert coarse.dynamic_range == pytest.approx(coarse.values.max() - coarse.values.min())


def test_pyramid_matches_the_scaled_camera():
    """A point projecting to a 2x2 block centre samples the block mean on the coarse image."""
    w, h = 64, 48
    values = np.random.default_rng(6).uniform(0, 255, size=(h, w))
    levels = pyramid(Image.from_array(values, prefilter_px=0.0), 3)   # interpolates the block means
    assert [im.shape for im in levels] == [(48, 64), (24, 32), (12, 16)]
    cam = Camera(np.array([[500.0, 2.0, 31.7], [0.0, 505.0, 24.2], [0.0, 0.0, 1.0]]), np.zeros(5),
                 [0.05, -0.1, 0.02], [1.0, 2.0, 300.0], (w, h))
    for scale in (1, 2):
        coarse_cam = cam.scaled(scale)
        assert coarse_cam.image_size == (levels[scale].shape[1], levels[scale].shape[0])
        b = 2 ** scale
        rng = np.random.default_rng(scale)
        ij = rng.integers(1, [h // b - 1, w // b - 1], size=(15, 2))
        centre = ij[:, ::-1] * b + (b - 1) / 2.0                 # fine (x, y) of the block centres
        ray = np.column_stack([centre, np.ones(len(centre))]) @ np.linalg.inv(cam.K).T
        X = (ray * 280.0 - cam.tvec) @ cam.R                      # back-projected world points
        np.testing.assert_allclose(cam.project(X), centre, atol=1e-9)
        x_coarse = coarse_cam.project(X)
        np.testing.assert_allclose(x_coarse, ij[:, ::-1], atol=1e-9)
        block_means = values.reshape(h // b, b, w // b, b).mean(axis=(1, 3))
        np.testing.assert_allclose(levels[scale].evaluate(x_coarse), block_means[ij[:, 0], ij[:, 1]],
                                   atol=1e-6)


@pytest.mark.parametrize("ext,dtype,top", [(".png", np.uint8, 255), (".tif", np.uint8, 255),
                                           (".png", np.uint16, 65535), (".tif", np.uint16, 65535)])
def test_read_back_8_and_16_bit(tmp_path, ext, dtype, top):
    a = np.random.default_rng(7).integers(0, top + 1, size=(21, 34)).astype(dtype)
    path = tmp_path / f"img{ext}"
    assert cv2.imwrite(str(path), a)
    image = read_image(path)
    assert image.prefilter_px == DEFAULT_PREFILTER_PX
    image = read_image(path, prefilter_px=0.0)
    np.testing.assert_array_equal(image.values, a.astype(float))
    assert image.values.dtype == np.float64
    assert image.dynamic_range == float(a.max()) - float(a.min())
    assert image.source == str(path)
    np.testing.assert_allclose(image.coefficients,
                               ndimage.spline_filter(a.astype(float), order=3, mode="mirror"))
    smooth = read_image(path, prefilter_px=0.7)
    np.testing.assert_array_equal(smooth.values, a.astype(float))      # raw values kept
    np.testing.assert_allclose(smooth.coefficients, ndimage.spline_filter(
        ndimage.gaussian_filter(a.astype(float), 0.7, mode="mirror"), order=3, mode="mirror"))


def test_read_colour_as_gray(tmp_path):
    bgr = np.random.default_rng(8).integers(0, 256, size=(10, 12, 3)).astype(np.uint8)
    path = tmp_path / "colour.png"
    cv2.imwrite(str(path), bgr)
    gray_cv = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(float)   # rounded to uint8 by cv2
    assert np.abs(read_image(path).values - gray_cv).max() <= 0.5 + 1e-9


def test_missing_unreadable_and_nan_files(tmp_path):
    missing = tmp_path / "nope.png"
    with pytest.raises(FileNotFoundError, match="nope.png"):
        read_image(missing)
    junk = tmp_path / "junk.tif"
    junk.write_bytes(b"this is not an image")
    with pytest.raises(ImageError, match="junk.tif"):
        read_image(junk)
    a = np.ones((6, 7), dtype=np.float32)
    a[1, 2] = np.nan
    a[3, 3] = np.inf
    path = tmp_path / "nan.tif"
    assert cv2.imwrite(str(path), a)
    with pytest.raises(ImageError, match=r"nan\.tif.*2 non-finite"):
        read_image(path)


def test_from_array_errors():
    with pytest.raises(ImageError, match="bad.*1 non-finite"):
        Image.from_array(np.array([[1.0, np.nan], [0.0, 2.0]]), source="bad")
    with pytest.raises(ImageError, match="2-D"):
        Image.from_array(np.zeros(5), source="flat")
    assert issubclass(ImageError, ValueError)
    with pytest.raises(ValueError, match="n_scales"):
        pyramid(_random_image(), 0)
    with pytest.raises(ImageError, match="too small"):
        Image.from_array(np.zeros((1, 4))).coarsen()


def test_image_arrays_are_read_only_and_caller_arrays_untouched():
    a = np.random.default_rng(9).uniform(0, 1, size=(5, 6))
    image = Image.from_array(a)
    direct = Image(a, a, 1.0, "direct")
    assert a.flags.writeable
    for arr in (image.values, image.coefficients, direct.values):
        with pytest.raises(ValueError):
            arr[0, 0] = 1.0
    with pytest.raises(ImageError, match="coefficients shape"):
        Image(a, a[:4], 1.0, "mismatch")


@pytest.mark.skipif(not image_module.COMPILED_KERNEL, reason="installed without the C kernel")
@pytest.mark.parametrize("shape", [(37, 53), (1, 9), (200, 150)])
def test_compiled_kernel_equals_its_numpy_twin(shape):
    image = _random_image(shape, seed=3)
    xy = _random_points(image, 200_000, seed=4, pad=40.0)          # mirror folds included
    xy[::997] = np.nan
    xy[1::1009, 0] = np.inf
    h, w = image.shape
    with parallel.threads(2):                                       # threaded split
        compiled = image.evaluate_with_gradient(xy)
    value, grad = np.empty(len(xy)), np.empty((len(xy), 2))
    bspline3.evaluate_numpy(image._padded, h, w, xy, value, grad)
    for a, b in zip(compiled, (value, grad)):
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-10 * image.dynamic_range, equal_nan=True)


# ----------------------------------------------------------------------------- image model
@pytest.mark.parametrize("sigma", [0.7, 0.9, 1.2])
def test_prefiltered_model_interpolates_the_gaussian_blurred_field(sigma):
    """The model of a sampled smooth field is the Gaussian-blurred field, interpolated.

    ``100 + 50 sin(kx x) cos(ky y)`` blurred by a Gaussian of ``sigma`` px is the same wave
    attenuated by ``exp(-sigma^2 (kx^2 + ky^2) / 2)`` (2.8 % at sigma 0.7, 10 % at 1.2, which
    a model without the prefilter misses). The sampled kernel differs from the continuous
    Gaussian by ``~2 exp(-2 pi^2 sigma^2)`` (1.3e-4 at 0.7) and the cubic spline's error is
    about 1e-3 of the amplitude at 23 px a period: asserted 1e-3 for the value, 1e-2 for
    the gradient (relative to amplitude and amplitude x wavenumber).
    """
    h, w = 80, 100
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    kx, ky = 2 * np.pi / 23.0, 2 * np.pi / 31.0
    image = Image.from_array(100.0 + 50.0 * np.sin(kx * xx) * np.cos(ky * yy), prefilter_px=sigma)
    xy = _random_points(image, 2000, seed=3)
    xy = xy[image.inside(xy, margin=8.0)]                          # away from the mirror border
    x, y = xy[:, 0], xy[:, 1]
    a = 50.0 * np.exp(-0.5 * sigma ** 2 * (kx ** 2 + ky ** 2))
    exact = 100.0 + a * np.sin(kx * x) * np.cos(ky * y)
    gx = a * kx * np.cos(kx * x) * np.cos(ky * y)
    gy = -a * ky * np.sin(kx * x) * np.sin(ky * y)
    assert 50.0 - a > 0.025 * 50.0                                  # the blur is there to see
    value, grad = image.evaluate_with_gradient(xy)
    assert np.abs(value - exact).max() < 1e-3 * 50.0
    assert np.abs(grad[:, 0] - gx).max() < 1e-2 * 50.0 * kx
    assert np.abs(grad[:, 1] - gy).max() < 1e-2 * 50.0 * ky
    # the raw pixels are kept as they are (the noise floor is estimated on them)
    np.testing.assert_array_equal(image.values, 100.0 + 50.0 * np.sin(kx * xx) * np.cos(ky * yy))


def test_default_model_and_zero_prefilter():
    a = np.random.default_rng(10).uniform(0, 255, size=(12, 15))
    assert Image.from_array(a).prefilter_px == DEFAULT_PREFILTER_PX
    bare = Image.from_array(a, prefilter_px=0.0)
    np.testing.assert_array_equal(bare.coefficients, ndimage.spline_filter(a, order=3, mode="mirror"))
    assert "prefilter_px=0" in repr(bare)


def test_with_values_keeps_the_model_and_the_source():
    rng = np.random.default_rng(11)
    a, b = rng.uniform(0, 255, size=(20, 30)), rng.uniform(0, 255, size=(20, 30))
    image = Image.from_array(a, "cam0.tif", prefilter_px=0.7)
    other = image.with_values(b)
    assert isinstance(other, Image) and other is not image
    assert other.prefilter_px == 0.7 and other.source == "cam0.tif"
    np.testing.assert_array_equal(other.values, b)
    np.testing.assert_array_equal(other.coefficients,
                                  Image.from_array(b, prefilter_px=0.7).coefficients)
    assert not np.allclose(other.coefficients, Image.from_array(b, prefilter_px=0.0).coefficients)
    assert other.dynamic_range == pytest.approx(b.max() - b.min())
    np.testing.assert_array_equal(image.values, a)                 # the original is untouched
    bare = Image.from_array(a, prefilter_px=0.0).with_values(b)
    assert bare.prefilter_px == 0.0
    np.testing.assert_array_equal(bare.coefficients, Image.from_array(b, prefilter_px=0.0).coefficients)


@pytest.mark.parametrize("sigma", [0.0, 0.5, 1.2])
def test_coarsen_and_pyramid_keep_the_model(sigma):
    """Each scale: 2x2 means of the raw values, then the same sigma in coarse pixels."""
    a = np.random.default_rng(12).uniform(0, 255, size=(48, 64))
    levels = pyramid(Image.from_array(a, "cam", prefilter_px=sigma), 3)
    raw = a
    for level in levels[1:]:
        raw = raw.reshape(raw.shape[0] // 2, 2, raw.shape[1] // 2, 2).mean(axis=(1, 3))
        assert level.prefilter_px == sigma
        np.testing.assert_allclose(level.values, raw, rtol=1e-14)
        smoothed = ndimage.gaussian_filter(raw, sigma, mode="mirror") if sigma else raw
        np.testing.assert_allclose(level.coefficients,
                                   ndimage.spline_filter(smoothed, order=3, mode="mirror"), atol=1e-9)
    assert levels[-1].with_values(levels[-1].values).prefilter_px == sigma


@pytest.mark.parametrize("bad", [-0.1, np.nan, np.inf, "wide"])
def test_prefilter_must_be_a_finite_non_negative_number(bad):
    a = np.ones((6, 7))
    with pytest.raises(ImageError, match=r"cam\.png.*prefilter_px must be a finite number >= 0|"
                                         r"cam\.png.*prefilter_px must be a number"):
        Image.from_array(a, "cam.png", prefilter_px=bad)
    with pytest.raises(ImageError, match="prefilter_px"):
        Image(a, a, 1.0, "direct", bad)


# ----------------------------------------------------------------------------- quintic B-spline
def _quintic(shape=(37, 53), seed=0, prefilter_px=0.0):
    a = np.random.default_rng(seed).uniform(0.0, 255.0, size=shape)
    return Image.from_array(a, "random", prefilter_px=prefilter_px, order=5)


def test_quintic_interpolant_reproduces_pixel_values():
    image = _quintic()
    h, w = image.shape
    yy, xx = np.mgrid[0:h, 0:w]
    xy = np.column_stack([xx.ravel(), yy.ravel()]).astype(float)
    value, _ = image.evaluate_with_gradient(xy)
    np.testing.assert_allclose(value, image.values.ravel(), rtol=0, atol=1e-9)
    np.testing.assert_array_equal(image.coefficients,
                                  ndimage.spline_filter(image.values, order=5, mode="mirror"))


@pytest.mark.parametrize("prefilter_px", [0.0, 0.7])
@pytest.mark.parametrize("shape", [(37, 53), (2, 9), (1, 6), (3, 4)])
def test_quintic_value_is_map_coordinates_and_gradient_its_derivative(shape, prefilter_px):
    """The 6x6 sum equals scipy's order-5 map_coordinates to round-off (also on and beyond the
    mirror border), its value-only pass (``evaluate``) the same sum, and its gradient the
    central difference of those values."""
    image = _quintic(shape, seed=1, prefilter_px=prefilter_px)
    xy = _random_points(image, 4000, seed=2, pad=20.0)
    value, grad = image.evaluate_with_gradient(xy)
    reference = ndimage.map_coordinates(image.coefficients, [xy[:, 1], xy[:, 0]], order=5,
                                        mode="mirror", prefilter=False)
    np.testing.assert_allclose(value, reference, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(image.evaluate(xy), value)          # the value-only pass
    h = 1e-5
    scale = np.abs(grad).max() if np.abs(grad).max() > 0 else 1.0
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        fd = (image.evaluate(xy + e) - image.evaluate(xy - e)) / (2 * h)
        assert np.abs(grad[:, k] - fd).max() / scale < 1e-6


def test_quintic_is_more_accurate_on_a_smooth_field():
    """Interpolation error O((k h)^6) against the cubic's O((k h)^4): at 23 px a period, 16 px
    from the border, the cubic misses by 1.9e-5 of the amplitude, the quintic by 1.5e-7.

    Nearer the border the mirror continuation of this (not mirror-symmetric) field dominates
    and decays inward as the spline filter's largest pole: 0.268^d cubic, 0.431^d quintic,
    so 8 px from the border the quintic's error is the larger (1.1e-4 against 1.9e-5).
    """
    h, w = 80, 100
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    kx, ky = 2 * np.pi / 23.0, 2 * np.pi / 31.0
    field = 100.0 + 50.0 * np.sin(kx * xx) * np.cos(ky * yy)
    cubic = Image.from_array(field, prefilter_px=0.0)
    quintic = Image.from_array(field, prefilter_px=0.0, order=5)
    xy = _random_points(quintic, 4000, seed=3)
    xy = xy[quintic.inside(xy, margin=16.0)]
    x, y = xy[:, 0], xy[:, 1]
    exact = 100.0 + 50.0 * np.sin(kx * x) * np.cos(ky * y)
    gx = 50.0 * kx * np.cos(kx * x) * np.cos(ky * y)
    gy = -50.0 * ky * np.sin(kx * x) * np.sin(ky * y)
    value, grad = quintic.evaluate_with_gradient(xy)
    error5 = np.abs(value - exact).max()
    error3 = np.abs(cubic.evaluate(xy) - exact).max()
    assert error5 < 1e-6 * 50.0 and error5 < 0.05 * error3
    assert np.abs(grad[:, 0] - gx).max() < 1e-5 * 50.0 * kx
    assert np.abs(grad[:, 1] - gy).max() < 1e-5 * 50.0 * ky


def test_quintic_inside_margin_covers_the_wider_support():
    """Default margin order / 2: 1.5 px cubic, 2.5 px quintic (support reaches no mirrored node)."""
    quintic = _quintic((20, 30))
    xy = np.array([[2.0, 2.0], [1.99, 5.0], [27.0, 17.0], [27.01, 5.0], [5.0, 17.01], [1.0, 1.0]])
    np.testing.assert_array_equal(quintic.inside(xy), [True, False, True, False, False, False])
    assert _random_image((20, 30)).inside(xy[-1:]).all()             # cubic: 1.0 px is inside
    assert quintic.inside(np.array([[1.0, 1.0]]), margin=1.5).all()


def test_order_is_kept_by_with_values_coarsen_pyramid_and_read(tmp_path):
    a = np.random.default_rng(13).uniform(0, 255, size=(48, 64))
    image = Image.from_array(a, "cam", prefilter_px=0.7, order=5)
    assert image.order == 5 and "order=5" in repr(image)
    assert Image.from_array(a).order == image_module.DEFAULT_ORDER == 3
    other = image.with_values(a[::-1])
    assert other.order == 5 and other.prefilter_px == 0.7
    raw = a
    for level in pyramid(image, 3)[1:]:
        raw = raw.reshape(raw.shape[0] // 2, 2, raw.shape[1] // 2, 2).mean(axis=(1, 3))
        assert level.order == 5
        np.testing.assert_allclose(level.coefficients, ndimage.spline_filter(
            ndimage.gaussian_filter(raw, 0.7, mode="mirror"), order=5, mode="mirror"), atol=1e-9)
    path = tmp_path / "cam.png"
    assert cv2.imwrite(str(path), a.astype(np.uint8))
    read = read_image(path, prefilter_px=0.0, order=5)
    assert read.order == 5
    np.testing.assert_allclose(read.coefficients, ndimage.spline_filter(read.values, order=5, mode="mirror"))


@pytest.mark.parametrize("bad", [4, 1, 0, "5", 5.5, True, None])
def test_order_must_be_3_or_5(bad):
    a = np.ones((6, 7))
    with pytest.raises(ImageError, match=r"cam\.png.*interpolation order must be one of 3, 5"):
        Image.from_array(a, "cam.png", order=bad)
    with pytest.raises(ImageError, match="interpolation order"):
        Image(a, a, 1.0, "direct", 0.0, bad)
