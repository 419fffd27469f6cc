"""Where the metric engine calls reference pixels sky, the aligned disparity below which they are sky
becomes sky everywhere (holoflow/depth/metric_alignment.py sky_disparity)."""

import numpy as np

from holoflow.depth.metric_alignment import sky_disparity


def test_the_threshold_separates_sky_from_surfaces_with_fewest_mistakes():
    g = np.random.default_rng(0)
    surface = g.uniform(0.25, 0.6, 900)  # 1 / m: walls 1.7-4 m
    sky = g.uniform(0.02, 0.15, 100)  # what alignment made of the sky: 7-50 m
    aligned = np.concatenate([surface, sky, [0.3]])
    is_sky = np.concatenate([np.zeros(900, bool), np.ones(100, bool), [True]])  # one mislabelled pixel
    t = sky_disparity(aligned, is_sky)
    assert sky.max() < t < surface.min()


def test_no_sky_among_the_references_turns_the_rule_off():
    a = np.linspace(0.2, 0.6, 500)
    assert sky_disparity(a, np.zeros(500, bool)) is None
    assert sky_disparity(a, np.arange(500) < 10) is None  # too few sky pixels to learn from
    assert sky_disparity(np.full(60, np.nan), np.ones(60, bool)) is None
