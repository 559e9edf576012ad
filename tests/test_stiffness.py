"""The project's stiffness evaluator (bench/stiffness.py) against analytic values."""

import math

import numpy as np
import pytest

from bench.stiffness import clip_to_window, directional, network, square_grid, stiffness, triangular_lattice

W = 0.4


def _lattice(rho, angle=0.0, offset=(0.37, 0.11)):
    return triangular_lattice(2 * math.sqrt(3) * W / rho, 40.0, angle=angle, offset=offset)


@pytest.mark.parametrize("angle", [0.0, 0.3, math.pi / 7])
def test_triangular_lattice_truss_limit_is_isotropic_three_eighths(angle):
    # stretch-dominated: the affine solution, C(theta)/rho = (1/3) sum cos^4 = 3/8 in every direction
    res = stiffness(_lattice(0.4, angle), W, window=30.0, centre=(0.0, 0.0), joints="pin")
    c = res.c_theta()
    assert np.allclose(c, 0.375, atol=0.002)
    assert res.isotropy > 0.995
    assert res.rho == pytest.approx(0.4, abs=0.005)
    # isotropic with Poisson's ratio 1/3: E = 8/9 C = 1/3
    assert res.e_min == pytest.approx(1 / 3, abs=0.002)


def test_triangular_lattice_rigid_joints_add_little_bending():
    pin = stiffness(_lattice(0.4), W, window=30.0, centre=(0.0, 0.0), joints="pin")
    rigid = stiffness(_lattice(0.4), W, window=30.0, centre=(0.0, 0.0), joints="rigid")
    assert pin.c_min < rigid.c_min < pin.c_min * 1.01
    assert rigid.isotropy > 0.99


def test_square_grid_along_the_lines_and_at_45_degrees():
    spacing = 2 * W / 0.2  # two families of lines, 20 %
    for joints in ("pin", "rigid"):
        res = stiffness(square_grid(spacing, 40.0, offset=(0.3, 0.2)), W, window=30.0, centre=(0, 0), joints=joints)
        C = res.normalised
        assert C[0, 0] == pytest.approx(0.5, abs=1e-9)  # each family holds half the material
        assert C[1, 1] == pytest.approx(0.5, abs=1e-9)
        assert abs(C[0, 1]) < 1e-9
        c45 = res.c_theta(np.array([math.pi / 4]))[0]
        e = res.e_theta(np.array([0.0, math.pi / 4]))
        assert e[0] == pytest.approx(0.5, rel=1e-6)
        if joints == "pin":
            assert c45 == pytest.approx(0.25, abs=1e-6)
            assert e[1] < 1e-6  # a pinned square grid shears freely
            assert res.isotropy == pytest.approx(0.5, abs=1e-6)
        else:
            assert 0.25 < c45 < 0.26
            assert 0.0 < e[1] < 0.03  # only the joints' bending resists shear
            assert res.e_min == pytest.approx(e[1], rel=0.05)


def test_directional_figures_of_an_isotropic_tensor():
    lam, mu = 1.0, 0.5
    C = np.array([[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu]])
    c, e = directional(C, np.linspace(0, math.pi, 7))
    assert np.allclose(c, lam + 2 * mu)
    assert np.allclose(e, 4 * mu * (lam + mu) / (lam + 2 * mu))


def test_network_splits_crossings_and_t_junctions():
    cross = np.array([[[0, 0], [2, 0]], [[1, -1], [1, 1]]], float)
    nodes, pieces = network(cross, 1e-6)
    assert len(nodes) == 5 and len(pieces) == 4
    tee = np.array([[[0, 0], [2, 0]], [[1, 0], [1, 1]]], float)
    nodes, pieces = network(tee, 1e-6)
    assert len(nodes) == 4 and len(pieces) == 3
    # a G-code line in two collinear moves, and a line ending on it from the side
    chain = np.array([[[0, 0], [1, 0]], [[1, 0], [3, 0]], [[2, 0], [2, 1]]], float)
    nodes, pieces = network(chain, 1e-6)
    assert len(nodes) == 5 and len(pieces) == 4
    lengths = np.hypot(*(nodes[pieces[:, 1]] - nodes[pieces[:, 0]]).T)
    assert lengths.sum() == pytest.approx(4.0)


def test_clip_to_window():
    seg = np.array([[[-10, 0], [10, 0]], [[0, -3], [0, 3]], [[20, 20], [30, 20]], [[-10, -10], [10, 10]]], float)
    out = clip_to_window(seg, (0, 0), 5.0)
    assert len(out) == 3
    assert np.allclose(np.abs(out[0]).max(axis=0), [5, 0])
    assert np.allclose(out[1], seg[1])
    assert np.allclose(np.abs(out[2]), 5.0)


def test_disconnected_pieces_carry_nothing_and_the_result_is_shift_invariant():
    lattice = _lattice(0.2)
    base = stiffness(lattice, W, window=30.0, centre=(0.0, 0.0))
    shifted = stiffness(lattice + 100.0, W, window=30.0, centre=(100.0, 100.0))
    assert np.allclose(base.C, shifted.C, rtol=1e-9, atol=1e-12)
    a = 2 * math.sqrt(3) * W / 0.2
    inside = np.array([0.37, 0.11]) + [a / 2, a * math.sqrt(3) / 6]  # a triangle's centroid
    loose = np.array([[inside - [0.1 * a, 0.0], inside + [0.1 * a, 0.0]]])  # touches no line
    with_loose = stiffness(np.concatenate((lattice, loose)), W, window=30.0, centre=(0.0, 0.0))
    assert np.allclose(with_loose.C, base.C, rtol=1e-9, atol=1e-12)
    assert with_loose.rho == pytest.approx(base.rho + 0.2 * a * W / 900.0)


@pytest.mark.parametrize("density", [0.2, 0.4])
def test_default_pattern_in_a_uniform_region_is_as_stiff_as_the_triangular_lattice(density):
    from shapely.geometry import box

    from DelaunayInfill import generate_infill

    area = box(0.8, 0.8, 79.2, 79.2)
    result = generate_infill(area, density, W, seed=3)
    res = stiffness(result.segments, W, window=30.0, centre=(40.0, 40.0))
    assert res.c_min > 0.97 * 0.375
    assert res.isotropy > 0.95
    # no node with more than 8 edges, no edge under a quarter of the spacing (inside the window)
    nodes, pieces = network(clip_to_window(result.segments, (40.0, 40.0), 15.0), 0.04)
    assert np.bincount(pieces.ravel()).max() <= 8
    inner = (np.abs(nodes[pieces] - 40.0) < 14.9).all(axis=(1, 2))
    length = np.hypot(*(nodes[pieces[inner, 1]] - nodes[pieces[inner, 0]]).T)
    assert length.min() > 0.25 * np.median(length)
