import numpy as np
import pytest
from skimage.color import deltaE_ciede2000, rgb2lab
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from fusiongs.errors import InputError
from fusiongs.eval.evaluate import compare_methods, format_table
from fusiongs.eval.metrics import affine_fit, delta_e00, image_metrics, psnr, quantize8, srgb_to_lab, ssim


def _pair(rng, h=40, w=52, c=3):
    gt = rng.random((h, w, c))
    pred = np.clip(gt + 0.05 * rng.standard_normal(gt.shape), 0, 1)
    return pred, gt


def test_psnr_matches_scikit_image_on_8bit(rng):
    pred, gt = _pair(rng)
    ref = peak_signal_noise_ratio(quantize8(gt), quantize8(pred), data_range=1.0)
    assert psnr(pred, gt) == pytest.approx(ref, abs=1e-9)


@pytest.mark.parametrize("c", [1, 3])
def test_ssim_matches_scikit_image_gaussian_population_valid(rng, c):
    pred, gt = _pair(rng, c=c)
    ref = structural_similarity(quantize8(gt), quantize8(pred), gaussian_weights=True, sigma=1.5,
                                use_sample_covariance=False, data_range=1.0, channel_axis=-1)
    assert ssim(pred, gt) == pytest.approx(ref, abs=1e-5)


def test_identical_images_give_infinite_psnr_and_unit_ssim(rng):
    _, gt = _pair(rng)
    assert psnr(gt, gt) == float("inf")
    assert ssim(gt, gt) == pytest.approx(1.0, abs=1e-6)


def test_affine_fit_recovers_scaled_and_offset_image(rng):
    gt = 0.2 + 0.6 * rng.random((30, 30, 3))
    pred = gt * np.array([0.5, 2.0, 1.3]) + np.array([0.1, -0.3, 0.05])
    np.testing.assert_allclose(affine_fit(pred, gt), gt, atol=1e-9)
    assert psnr(pred, gt) < 20


def test_shape_mismatch_is_named():
    with pytest.raises(InputError, match="image shape"):
        psnr(np.zeros((4, 4, 3)), np.zeros((4, 5, 3)))


def _neutral_l_star(v: float) -> float:
    """CIE L* of the sRGB grey (v, v, v) by hand: IEC 61966-2-1 decoding, Y = linear (the Y row of
    the sRGB matrix sums to 1), L* = 116 Y^(1/3) - 16 above (6/29)^3."""
    lin = v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4
    return 116.0 * lin ** (1 / 3) - 16.0 if lin > (6 / 29) ** 3 else lin * (29 / 3) ** 3


def test_delta_e00_of_identical_images_is_zero(rng):
    _, gt = _pair(rng)
    assert delta_e00(gt, gt) == 0.0


def test_delta_e00_white_to_black_is_100_and_grey_to_black_follows_the_lightness_formula():
    white, black = np.ones((4, 4, 3)), np.zeros((4, 4, 3))
    assert delta_e00(white, black) == pytest.approx(100.0, abs=1e-3)
    # neutral pair (a* = b* = 0): CIEDE2000 reduces to ΔL* / S_L with S_L taken at the mean L*
    v = 128 / 255
    l1 = _neutral_l_star(v)
    lm = l1 / 2
    s_l = 1 + 0.015 * (lm - 50) ** 2 / np.sqrt(20 + (lm - 50) ** 2)
    assert l1 == pytest.approx(53.585, abs=1e-3)  # not 76.19 (128/255 taken as linear): sRGB decoded
    assert delta_e00(np.full((4, 4, 3), v), black) == pytest.approx(l1 / s_l, abs=1e-3)


def test_srgb_red_has_its_published_lab_value():
    # CIE L*a*b* (D65) of sRGB (1, 0, 0): 53.24, 80.09, 67.20 (to 0.03 across sRGB matrix roundings)
    np.testing.assert_allclose(srgb_to_lab(np.array([[[1.0, 0.0, 0.0]]]))[0, 0], [53.24, 80.09, 67.20],
                               atol=0.03)


def test_delta_e00_matches_scikit_image_on_8bit(rng):
    pred, gt = _pair(rng)
    ref = deltaE_ciede2000(rgb2lab(quantize8(pred)), rgb2lab(quantize8(gt))).mean()
    assert delta_e00(pred, gt) == pytest.approx(ref, abs=0.01)
    assert 1 < ref < 20  # a real colour error, not a degenerate pair


def test_delta_e00_of_grey_images_is_that_of_equal_rgb(rng):
    pred, gt = _pair(rng, c=1)
    assert delta_e00(pred, gt) == pytest.approx(delta_e00(np.repeat(pred, 3, -1), np.repeat(gt, 3, -1)))


def test_affine_metrics_carry_delta_e00_after_the_fit(rng):
    gt = 0.2 + 0.6 * rng.random((30, 30, 3))
    pred = gt * np.array([0.5, 2.0, 1.3]) + np.array([0.1, -0.3, 0.05])
    assert "delta_e00" not in image_metrics(pred, gt)
    assert image_metrics(pred, gt, delta_e=True)["delta_e00"] > 5  # raw colours are off
    assert image_metrics(pred, gt, affine=True)["delta_e00"] < 0.5  # the fit restores them
    res = compare_methods({"fusiongs": {"novel_000": pred}}, {"novel_000": gt}, affine=True)
    assert res["mean"]["novel"]["fusiongs"]["delta_e00"] < 0.5
    assert "dE00" in format_table(res)
    assert "dE00" not in format_table(compare_methods({"fusiongs": {"novel_000": pred}}, {"novel_000": gt}))


def test_global_affine_fit_is_one_fit_over_all_views():
    from fusiongs.eval.metrics import global_affine_fit

    rng = np.random.default_rng(3)
    gts = [rng.uniform(0.1, 0.9, (6, 5, 3)) for _ in range(3)]
    # one gain and offset per channel for every view: the joint fit recovers the truth exactly
    preds = [(g - 0.05) / 1.7 for g in gts]
    for f, g in zip(global_affine_fit(preds, gts), gts):
        np.testing.assert_allclose(f, g, atol=1e-12)
    # a second view brighter than the first: each view alone fits exactly, the joint fit cannot
    preds = [gts[0] * 0.5, gts[1] * 0.5 + 0.2]
    joint = global_affine_fit(preds, gts[:2])
    assert max(np.abs(j - g).max() for j, g in zip(joint, gts[:2])) > 0.05
    for p, g in zip(preds, gts[:2]):
        np.testing.assert_allclose(affine_fit(p, g), g, atol=1e-12)


def test_global_affine_fit_refuses_unequal_lists():
    from fusiongs.errors import InputError
    from fusiongs.eval.metrics import global_affine_fit

    with pytest.raises(InputError, match="preds/gts"):
        global_affine_fit([np.zeros((2, 2, 3))], [])
