"""The shared numpy arm models (arm_models.py) checked on their own: the closed-form link
matrices equal the products of elementary motions they stand for, and the zero poses land
where the makers' geometry puts the flange (UR5: x = a2 + a3, y = -(d4 + d6), z = d1 - d5;
Panda: x = a7 = 88 mm, z = 333 + 316 + 384 - 107 mm)."""

import numpy as np

from arm_models import mod_link, panda, rx, rz, std_link, tr, ur5

RNG = np.random.default_rng(4)


def test_links_are_their_elementary_products_and_broadcast():
    th, al = RNG.uniform(-3, 3, (2, 5))
    d, a = RNG.uniform(-500, 500, (2, 5))
    assert np.allclose(std_link(th, d, a, al), rz(th) @ tr(0, 0, d) @ tr(a, 0, 0) @ rx(al), atol=1e-12)
    assert np.allclose(mod_link(al, a, th, d), rx(al) @ tr(a, 0, 0) @ rz(th) @ tr(0, 0, d), atol=1e-12)
    assert std_link(th[0], d[0], a[0], al[0]).shape == (4, 4)


def test_zero_poses_are_the_makers_home_geometry():
    assert np.allclose(ur5([0.0] * 6)[:3, 3], [-425 - 392.25, -(109.15 + 82.3), 89.159 - 94.65], atol=1e-9)
    assert np.allclose(panda([0.0] * 7)[:3, 3], [88, 0, 333 + 316 + 384 - 107], atol=1e-9)
    assert np.allclose(panda([0.0] * 7)[:3, 2], [0, 0, -1], atol=1e-12)   # flange points down
