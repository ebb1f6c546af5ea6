import numpy as np
import pytest
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from fusiongs.errors import InputError
from fusiongs.eval.metrics import affine_fit, psnr, quantize8, ssim


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
