"""Solids in the air (issue 23): obstacles, walls, inflow profiles, forces on solids."""

import math

import flagsim
import numpy as np
import pytest
from _air import close_solid_faces, max_abs_diff, plate, random_field, solid_face_masks
from flagsim import forces
from flagsim.study import accuracy_solids

ITERATIVE = ["pcg", "multigrid"]

# Most solids here are a few cells across, which warns (the wake is not resolved): tests about
# the warning catch it with pytest.warns; the others do not need the wake.
pytestmark = pytest.mark.filterwarnings("ignore:air.obstacles.*cells across:UserWarning")


def obstacles():
    return [
        flagsim.ObstacleParams(shape="sphere", center=(0.45, 0.5, 0.4), radius=0.22),
        flagsim.ObstacleParams(
            shape="box", center=(0.9, 0.35, 0.4), half_size=(0.1, 0.15, 0.2), slip="free_slip"
        ),
    ]


@pytest.mark.parametrize("boundary", ["periodic", "tunnel"])
@pytest.mark.parametrize("pressure", ITERATIVE)
def test_projection_with_solids_leaves_no_divergence_and_no_flux(boundary, pressure):
    tol = 1e-9
    fluid = flagsim.Fluid(
        resolution=(12, 10, 8),
        cell_size=0.1,
        origin=(0, 0, 0),
        boundary=boundary,
        pressure=pressure,
        viscosity=1e-3,
        pcg_tolerance=tol,
        wind=(1.0, 0, 0) if boundary == "tunnel" else None,
        obstacles=obstacles(),
        walls="no_slip" if boundary == "tunnel" else None,
    )
    assert (fluid.solid_cells() == 1).sum() > 0 and (fluid.solid_cells() == 2).sum() > 0
    random_field(fluid, 3)
    before = np.abs(fluid.divergence()).max()
    for _ in range(3):
        fluid.step(0.01)
        assert fluid.stats["pressure_converged"]
        div = fluid.divergence()
        assert np.abs(div).max() <= tol * before * 1.01
        assert np.all(div[fluid.solid_cells() > 0] == 0)
        for name, mask in zip("uvw", solid_face_masks(fluid)):
            assert np.all(getattr(fluid, name)[mask] == 0), name  # zero flux, exactly


@pytest.mark.parametrize("precision", ["double", "float"])
@pytest.mark.parametrize("boundary", ["periodic", "tunnel"])
def test_multigrid_and_pcg_agree_with_solid_cells(boundary, precision):
    tol = 1e-10 if precision == "double" else 1e-5
    fluids = {}
    for pressure in ("multigrid", "pcg"):
        fluid = flagsim.Fluid(
            resolution=(16, 12, 10),
            cell_size=0.1,
            origin=(0, 0, 0),
            boundary=boundary,
            pressure=pressure,
            precision=precision,
            viscosity=0.0,
            pcg_tolerance=tol,
            wind=(1.0, 0.0, 0.0),
        )
        fluid.set_solid_cells(plate(fluid.resolution))
        random_field(fluid, 7)
        close_solid_faces(fluid)
        fluid.step(1e-4)  # advection moves the field by a thousandth of a cell: the projection
        assert fluid.stats["pressure_converged"]
        fluids[pressure] = fluid
    mg, pcg = fluids["multigrid"], fluids["pcg"]
    assert 0 < mg.stats["pressure_iterations"] <= 15 < pcg.stats["pressure_iterations"]
    scale = max(float(np.abs(getattr(pcg, n)).max()) for n in "uvw")
    assert max_abs_diff(mg, pcg) < 1e3 * tol * scale


@pytest.mark.parametrize("precision", ["double", "float"])
@pytest.mark.parametrize("boundary", ["periodic", "tunnel"])
def test_multigrid_and_pcg_agree_with_obstacles(boundary, precision):
    tol = 1e-10 if precision == "double" else 1e-5
    runs = {}
    for pressure in ("multigrid", "pcg"):
        fluid = flagsim.Fluid(
            resolution=(16, 12, 10),
            cell_size=0.1,
            origin=(0, 0, 0),
            boundary=boundary,
            pressure=pressure,
            precision=precision,
            viscosity=1e-3,
            pcg_tolerance=tol,
            wind=(1.0, 0, 0) if boundary == "tunnel" else None,
            obstacles=obstacles(),
        )
        random_field(fluid, 5)
        fluid.step(0.01, 3)
        assert fluid.stats["pressure_converged"]
        runs[pressure] = fluid
    mg, pcg = runs["multigrid"], runs["pcg"]
    assert mg.stats["pressure_iterations"] < pcg.stats["pressure_iterations"]
    scale = max(float(np.abs(getattr(pcg, n)).max()) for n in "uvw")
    for n in "uvw":  # one problem: apart by what the tolerance allows (3 steps of it)
        assert np.abs(getattr(mg, n) - getattr(pcg, n)).max() < 1e3 * tol * scale, n


def test_free_slip_keeps_a_flow_along_a_solid_and_no_slip_stops_it_as_stokes_says():
    """A slab through a periodic box, air sliding along it at U: free-slip leaves the flow as it
    was; no-slip starts Stokes' first problem, u = U erf(d / (2 sqrt(nu t))) beside the wall."""
    n, h, nu, U, dt, steps = 32, 1 / 32, 0.01, 1.0, 0.005, 100
    for slip in ("free_slip", "no_slip"):
        slab = flagsim.ObstacleParams(
            shape="box", center=(0.5, 0.5, 0.5), half_size=(5, 1.01 / n, 5), slip=slip
        )
        fluid = flagsim.Fluid(
            resolution=(4, n, 4),
            cell_size=h,
            origin=(0, 0, 0),
            pressure="pcg",
            viscosity=nu,
            obstacles=[slab],
        )
        fluid.set_velocity(lambda p: np.tile([U, 0.0, 0.0], (len(p), 1)))
        fluid.step(dt, steps)
        u = fluid.u[2, :, 2]
        solid = fluid.solid_cells()[2, :, 2] > 0
        if slip == "free_slip":
            np.testing.assert_allclose(u[~solid], U, rtol=0, atol=1e-12)
            continue
        # Distance of each u node (cell centre in y) from the slab's upper face.
        top = (np.nonzero(solid)[0].max() + 1) * h
        y = (np.arange(n) + 0.5) * h
        above = (y > top) & (y < top + 0.25)  # the other wall is 0.9 away: not felt yet
        d = y[above] - top
        t = fluid.time
        exact = np.array([U * math.erf(x / (2 * math.sqrt(nu * t))) for x in d])
        np.testing.assert_allclose(u[above], exact, atol=0.01)
        assert u[above][0] < 0.5 * U  # the wall has stopped the air beside it


# docs/accuracy.md, "Observed convergence orders": the whole method at fixed CFL is first order
# (the fractional step's splitting error at a no-slip wall is O(dt)); with dt ~ h^2 the walls'
# mirror shows its second order.
POISEUILLE_ORDER = {"cfl": (0.9, 1.4), "dt~h^2": (1.8, 2.2)}


@pytest.mark.parametrize("refinement", ["cfl", "dt~h^2"])
def test_poiseuille_profile_converges_at_the_documented_order(refinement):
    errors = [
        accuracy_solids.run_poiseuille(ny, "semi_lagrangian", refinement)["error"] for ny in (8, 16)
    ]
    order = math.log2(errors[0] / errors[1])
    lo, hi = POISEUILLE_ORDER[refinement]
    assert lo <= order <= hi, (errors, order)
    assert errors[1] < 0.015


def test_parabolic_inflow_enters_with_the_winds_flux():
    fluid = flagsim.Fluid(
        resolution=(6, 12, 4),
        cell_size=0.1,
        origin=(0, 0, 0),
        boundary="tunnel",
        pressure="pcg",
        wind=(2.0, 0, 0),
        walls={"y_min": "no_slip", "y_max": "no_slip"},
        inflow_profile="parabolic",
    )
    inflow = fluid.u[0]
    assert inflow.mean() == pytest.approx(2.0, rel=1e-14)
    s = (np.arange(12) + 0.5) / 12
    np.testing.assert_allclose(inflow[:, 0], 2.0 * 6 * s * (1 - s), atol=2.0 / 12**2)
    fluid.step(0.01, 3)
    assert fluid.u[0].mean() == pytest.approx(2.0, rel=1e-14)


def test_obstacle_force_is_pressure_drag_on_a_blocked_tunnel():
    """A box filling the middle of a tunnel's cross-section except a gap: the air pushes it
    downstream, and the force starts at zero."""
    box = flagsim.ObstacleParams(shape="box", center=(0.6, 0.5, 0.4), half_size=(0.1, 0.3, 0.5))
    fluid = flagsim.Fluid(
        resolution=(16, 10, 8),
        cell_size=0.1,
        origin=(0, 0, 0),
        boundary="tunnel",
        pressure="pcg",
        wind=(1.0, 0, 0),
        obstacles=[box],
        viscosity=1e-3,
    )
    assert fluid.obstacle_force(0) == (0.0, 0.0, 0.0)
    fluid.step(0.02, 20)
    fx, fy, fz = fluid.obstacle_force(0)
    assert fx > 0
    assert abs(fz) < 1e-6 * fx  # the box and the flow are symmetric in z
    with pytest.raises(ValueError, match=r"index should be an obstacle index in \[0, 1\)"):
        fluid.obstacle_force(1)


def test_add_obstacle_holds_its_faces_at_once_and_warns_when_thin():
    fluid = flagsim.Fluid(resolution=(8, 8, 8), cell_size=0.125, origin=(0, 0, 0), pressure="pcg")
    fluid.set_velocity(lambda p: np.tile([1.0, 0.5, 0.0], (len(p), 1)))
    with pytest.warns(UserWarning, match=r"obstacles\[0\] is 3.2 cells across, fewer than the 8"):
        fluid.add_obstacle(flagsim.ObstacleParams(shape="sphere", center=(0.5,) * 3, radius=0.2))
    for name, mask in zip("uvw", solid_face_masks(fluid)):
        assert mask.any() and np.all(getattr(fluid, name)[mask] == 0)
    with pytest.warns(UserWarning, match="covers no cell centre"):
        fluid.add_obstacle(
            flagsim.ObstacleParams(shape="sphere", center=(0.125, 0.125, 0.125), radius=0.01)
        )
    assert len(fluid.obstacles) == 2 and len(fluid.warnings()) == 2


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (
            dict(pressure="fft", obstacles="one"),
            r"pressure should be \"pcg\" or \"multigrid\" with obstacles",
        ),
        (dict(walls="no_slip"), r"wall_y_min should be \"free_slip\" with boundary \"periodic\""),
        (dict(walls={"x_min": "no_slip"}), "walls should be keys among y_min"),
        (
            dict(boundary="tunnel", pressure="pcg", inflow_profile="parabolic"),
            'inflow_profile should be "uniform" unless both y walls or both z walls',
        ),
        (dict(walls="sticky", boundary="tunnel", pressure="pcg"), "walls should be one of"),
    ],
)
def test_bad_solid_settings_are_named(kwargs, message):
    if kwargs.get("pressure") == "fft" and not flagsim.has_fftw():
        pytest.skip("built without FFTW: fft cannot be asked for")
    if kwargs.get("obstacles") == "one":
        kwargs["obstacles"] = [flagsim.ObstacleParams(shape="sphere", center=(0.5,) * 3)]
    with pytest.raises(ValueError, match=message):
        flagsim.Fluid(resolution=(8, 8, 8), cell_size=0.125, origin=(0, 0, 0), **kwargs)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("radius", -1.0, r"obstacle\.radius should be"),
        ("axis", (0, 0, 0), r"obstacle\.axis should be a non-zero vector"),
        ("shape", "cone", r"obstacle\.shape should be one of"),
        ("slip", "glue", r"obstacle\.slip should be one of"),
    ],
)
def test_bad_obstacle_fields_are_named(field, value, message):
    o = flagsim.ObstacleParams()
    with pytest.raises(ValueError, match=message):
        setattr(o, field, value)


def test_toml_obstacles_walls_and_the_pole(tmp_path):
    text = """
[air]
model = "grid"
boundary = "tunnel"
pressure = "pcg"
resolution = [24, 48, 16]
cell_size = 0.0625
origin = [-0.5, -2.6, -0.5]
pole_obstacle = true
wall_y_min = "no_slip"
wall_y_max = "no_slip"
inflow_profile = "parabolic"

[[air.obstacles]]
shape = "box"
center = [0.6, -1.5, 0.0]
half_size = [0.2, 0.2, 0.2]
slip = "free_slip"
"""
    path = tmp_path / "wake.toml"
    path.write_text(text)
    scene = flagsim.Scene.load(path)
    assert scene.air.pole_obstacle and scene.air.wall_y_min == "no_slip"
    assert scene.air.obstacles[0].slip == "free_slip"
    again = flagsim.Scene.from_dict(scene.to_dict())
    assert again.air.obstacles[0].center == (0.6, -1.5, 0.0) and again.air.pole_obstacle
    with pytest.warns(UserWarning, match=r"obstacles\[1\] is 1.76 cells across"):
        sim = flagsim.Simulation(scene)
    sim.step(2)
    # The pole (obstacle 1, after the scene's own) is solid along its axis, air beside it.
    cells = sim.fluid.solid_cells()
    pole = scene.pole
    origin, h = np.array(scene.air.origin), scene.air.cell_size
    i, k = ((np.array([pole.base[0], pole.base[2]]) - origin[[0, 2]]) / h).astype(int)
    j = int((pole.base[1] + 0.5 * pole.height - origin[1]) / h)
    assert cells[i, j, k] == 2
    assert cells[i + 2, j, k] == 0 and cells[i - 2, j, k] == 0
    centres = [origin[d] + h * (np.arange(n) + 0.5) for d, n in enumerate(cells.shape)]
    inside = [np.abs(c - o) <= 0.2 for c, o in zip(centres, (0.6, -1.5, 0.0))]
    assert (cells == 1).sum() == np.prod([m.sum() for m in inside]) > 0


def test_pole_obstacle_needs_a_grid_and_a_pole():
    s = flagsim.Scene.paper()
    s.air.pole_obstacle = True
    s.pole.enabled = False
    with pytest.raises(ValueError, match="air.pole_obstacle should be false unless"):
        s.validate()
    s.pole.enabled = True
    if flagsim.has_fftw():
        s.air.pressure = "fft"
        with pytest.raises(
            ValueError, match=r"air.pressure should be \"pcg\" or \"multigrid\" with obstacles"
        ):
            s.validate()


def test_periodic_mean_flow_is_held_over_the_air_not_the_solid():
    slab = flagsim.ObstacleParams(shape="box", center=(0.5, 0.5, 0.5), half_size=(5, 0.07, 5))
    fluid = flagsim.Fluid(
        resolution=(4, 16, 4),
        cell_size=1 / 16,
        origin=(0, 0, 0),
        pressure="pcg",
        viscosity=0.01,
        obstacles=[slab],
        wind=[(0.0, (1.0, 0.0, 0.0)), (1.0, (2.0, 0.0, 0.0))],
    )
    air = ~solid_face_masks(fluid)[0]
    fluid.step(0.01, 50)
    assert fluid.u[air].mean() == pytest.approx(1.5, rel=1e-12)
    assert np.all(fluid.u[~air] == 0)


def test_force_history_measures_a_known_frequency_and_coefficients():
    t = np.arange(1, 2001) * 0.01
    f = np.stack([2.0 + 0 * t, 0.5 * np.sin(2 * np.pi * 1.7 * t + 0.3), 0 * t], axis=1)
    h = forces.ForceHistory(t, f)
    assert h.shedding_frequency(axis=1, after=1.0) == pytest.approx(1.7, rel=1e-4)
    assert math.isnan(h.shedding_frequency(axis=0))  # a constant never crosses its mean
    np.testing.assert_allclose(h.mean(after=5.0)[0], 2.0)
    np.testing.assert_allclose(h.coefficients(1.2, 2.0, 0.5)[:, 0], 2.0 / (0.5 * 1.2 * 4 * 0.5))
    with pytest.raises(ValueError, match="density, speed and area should be > 0"):
        h.coefficients(1.2, 0.0, 1.0)
    with pytest.raises(ValueError, match="after should be below the last time"):
        h.mean(after=100.0)


def test_forces_module_examples_run():
    import doctest

    assert doctest.testmod(forces).failed == 0


# The CI-sized cylinder (6 cells per diameter, blockage 12.5 %, 60 D / U), measured: St 0.1645,
# C_D 1.71. St lands within 5 % of Williamson's 0.164; the narrow domain's blockage raises the
# drag above the unconfined 1.32-1.34 (the full study, docs/reports/accuracy.md, shows it fall
# as the domain widens and the grid refines), so C_D's band here is the blocked one.
CI_CYLINDER_BANDS = {"strouhal": (0.95, 1.05), "drag_coefficient": (1.33, 1.85)}


def test_a_ci_sized_cylinder_sheds_at_the_published_strouhal_number():
    r = accuracy_solids.run_cylinder(6, "maccormack", **accuracy_solids.QUICK_CYLINDER)
    st_lo, st_hi = CI_CYLINDER_BANDS["strouhal"]
    assert st_lo * accuracy_solids.ST_REF <= r["strouhal"] <= st_hi * accuracy_solids.ST_REF, r
    cd_lo, cd_hi = CI_CYLINDER_BANDS["drag_coefficient"]
    assert cd_lo <= r["drag_coefficient"] <= cd_hi, r
