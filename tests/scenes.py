"""Synthetic scenes of the claims tests (helpers; the session fixtures are in tests/conftest.py)."""
import dataclasses
import functools

import numpy as np

from fesdic_core.imaging.image import Image
from fesdic_core.synthetic.render import demo_cameras, render_stereo, speckle_mm_for
from fesdic_core.synthetic.specimen import Specimen, twisted_plate

#: the demo's scene (georeg_app.shape.demo.DEMO) with images of 500 x 333 px instead of
#: 1224 x 816: a 180 x 50 mm plate with a 14 mm hole seen over its central 100 mm, twist
#: of 1 mm at the corners of the view plus a 0.2 mm waviness (not in any spline level),
#: two cameras at 25 deg, 4 px speckle, noise of 2 gray levels.
SMALL_DEMO = dict(length_mm=180.0, width_mm=50.0, view_mm=100.0, hole_radius_mm=14.0,
                  corner_mm=1.0, waviness_mm=0.2, noise_std=2.0, image_size=(500, 333),
                  field_mm=112.0, stereo_angle_deg=25.0)

#: a flat 60 x 40 mm plate with a Gaussian bump of 0.3 mm, sigma 2 mm (width at half
#: height 4.7 mm), off-centre: a feature far shorter than a 30 mm Tikhonov length or the
#: 30 x 20 mm knot spans of a two-level spline of the plate
BUMP = dict(amplitude=0.3, sigma=2.0, centre=(8.0, 5.0))


@dataclasses.dataclass(frozen=True, eq=False)
class Scene:
    specimen: Specimen
    cameras: tuple            # the exact cameras
    arrays: tuple             # the two rendered images, gray levels (h, w)

    @property
    def images(self):
        return tuple(Image.from_array(a, source=f"synthetic cam{k}") for k, a in enumerate(self.arrays))


def small_demo_scene() -> Scene:
    """The demo's twisted open-hole plate with waviness and noise, 500 x 333 px."""
    d = SMALL_DEMO
    cameras = demo_cameras(image_size=d["image_size"], stereo_angle_deg=d["stereo_angle_deg"],
                           field_mm=d["field_mm"])
    specimen = twisted_plate(d["length_mm"], d["width_mm"], corner_mm=d["corner_mm"],
                             hole_radius_mm=d["hole_radius_mm"], waviness_mm=d["waviness_mm"],
                             view_length_mm=d["view_mm"], speckle_mm=speckle_mm_for(cameras[0], 4.0),
                             seed=7)
    arrays = render_stereo(specimen, cameras, supersample=3, noise_std=d["noise_std"], seed=11,
                           progress=False)
    return Scene(specimen, tuple(cameras), tuple(arrays))


def _bump(x, y, amplitude, sigma, centre):
    return amplitude * np.exp(-((x - centre[0]) ** 2 + (y - centre[1]) ** 2) / (2 * sigma ** 2))


def _bump_gradient(x, y, amplitude, sigma, centre):
    g = _bump(x, y, amplitude, sigma, centre)
    return -g * (x - centre[0]) / sigma ** 2, -g * (y - centre[1]) / sigma ** 2


def bump_specimen(speckle_mm: float = 0.3, seed: int = 5) -> Specimen:
    """Flat 60 x 40 mm plate carrying the bump ``BUMP`` (a custom ``Specimen`` surface)."""
    return Specimen(60.0, 40.0, height=functools.partial(_bump, **BUMP),
                    height_gradient=functools.partial(_bump_gradient, **BUMP),
                    speckle_mm=speckle_mm, seed=seed)


def bump_scene() -> Scene:
    """The bump plate, 480 x 320 px over a 72 mm field (0.15 mm/px), noise of 2 gray levels."""
    cameras = demo_cameras(image_size=(480, 320), field_mm=72.0)
    specimen = bump_specimen(speckle_mm_for(cameras[0], 4.0))
    arrays = render_stereo(specimen, cameras, supersample=3, noise_std=2.0, seed=2, progress=False)
    return Scene(specimen, tuple(cameras), tuple(arrays))


# ----------------------------------------------------------------------------- the family
#: the shape family of issue 10 item 4 ("never worse than plain FE"): one square 60 mm plate
#: seen by the demo's rig (two cameras at 25 deg, 400 mm), 4 px speckle, noise of 2 gray
#: levels, pixel-integrated by 6 x 6 rays (3 x 3, as the scenes above, leaves a misfit that
#: a fine FE mesh fits as shape: see tests/adapters/test_never_worse_than_fe.py). Its shapes: flat, or a
#: Gaussian bump of amplitude 0.5 mm and sigma = width / divisor (divisors 2 to 20: from
#: half the plate's width, a dome, down to a twentieth, 3 mm), centred off the plate's
#: centre. The FE mesh that goes with it (``elements``, Q9) has elements of 1.5 mm, half
#: the narrowest sigma, and 16 px per element side: 40 x 40 elements over 640 x 640 px of
#: plate (0.094 mm/px, about the demo's 0.1 mm/px), images of 704 x 736 px.
FAMILY = dict(length_mm=60.0, width_mm=60.0, amplitude_mm=0.5, centre_mm=(6.0, 3.0),
              divisors=(2, 5, 10, 20), elements=(40, 40), pixel_mm=1.5 / 16,
              image_size=(704, 736), stereo_angle_deg=25.0, speckle_px=4.0, noise_std=2.0,
              supersample=6, seed=5, noise_seed=2)

#: the same family at the demo's scale (0.1 mm/px, 1200 x 1000 px images): a 96 x 80 mm
#: plate, sigma from 40 down to 4 mm, a 48 x 40 Q9 mesh of 2 mm elements (20 px each)
FAMILY_DEMO_SCALE = dict(FAMILY, length_mm=96.0, width_mm=80.0, centre_mm=(9.6, 4.0),
                         elements=(48, 40), pixel_mm=0.1, image_size=(1200, 1000))


def family_cameras(family: dict = FAMILY) -> tuple:
    """The family's exact stereo rig: the demo's cameras at ``pixel_mm`` per pixel."""
    return demo_cameras(image_size=family["image_size"],
                        stereo_angle_deg=family["stereo_angle_deg"],
                        field_mm=family["image_size"][0] * family["pixel_mm"])


def family_sigma(divisor: int, family: dict = FAMILY) -> float:
    """The bump's sigma (mm): the plate's width over ``divisor``."""
    return family["width_mm"] / float(divisor)


def family_specimen(divisor: int | None, speckle_mm: float, family: dict = FAMILY) -> Specimen:
    """The family's plate: flat (``divisor`` None) or with the bump of sigma = width / divisor."""
    if divisor is None:
        return Specimen(family["length_mm"], family["width_mm"], speckle_mm=speckle_mm,
                        seed=family["seed"])
    bump = dict(amplitude=family["amplitude_mm"], sigma=family_sigma(divisor, family),
                centre=family["centre_mm"])
    return Specimen(family["length_mm"], family["width_mm"],
                    height=functools.partial(_bump, **bump),
                    height_gradient=functools.partial(_bump_gradient, **bump),
                    speckle_mm=speckle_mm, seed=family["seed"])


def family_scene(divisor: int | None, family: dict = FAMILY) -> Scene:
    """One shape of the family rendered by the core's ray caster (same speckle and noise
    seeds for every shape: the shapes differ by their surface only)."""
    cameras = family_cameras(family)
    specimen = family_specimen(divisor, speckle_mm_for(cameras[0], family["speckle_px"]), family)
    arrays = render_stereo(specimen, cameras, supersample=family["supersample"],
                           noise_std=family["noise_std"], seed=family["noise_seed"], progress=False)
    return Scene(specimen, tuple(cameras), tuple(arrays))


# ----------------------------------------------------------------------------- CAD parts
#: issue 11's parts, each nominal given as an IGES file (``write_iges``): a cylindrical panel
#: (nominal radius 100 mm, 50 mm along its axis x, 40 mm across) whose true radius is 95 mm
#: with a waviness of 30 um along x; and a folded plate of two flat 30 x 40 mm faces meeting
#: at a crease along x = 0 (nominal slope 0.1 on each side, true slope 0.105 with a bow of
#: 40 um across). 480 x 320 px over 72 mm, 4 px speckle, noise of 2 gray levels.
CAD_PARTS = dict(radius_mm=100.0, true_radius_mm=95.0, wave_mm=0.03, panel_mm=(50.0, 40.0),
                 slope=0.1, true_slope=0.105, bow_mm=0.04, folded_mm=(60.0, 40.0))


def _panel_height(x, y, radius, wave, length):
    return np.sqrt(radius ** 2 - y ** 2) - radius + wave * np.cos(np.pi * x / length)


def _panel_gradient(x, y, radius, wave, length):
    return (-wave * np.pi / length * np.sin(np.pi * x / length) + 0 * y,
            -y / np.sqrt(radius ** 2 - y ** 2) + 0 * x)


def _folded_height(x, y, slope, bow, width):
    return -slope * np.abs(x) + bow * np.cos(np.pi * y / width)


def _folded_gradient(x, y, slope, bow, width):
    return -slope * np.sign(x) + 0 * y, -bow * np.pi / width * np.sin(np.pi * y / width) + 0 * x


def cad_nominal(part: str) -> list:
    """The nominal faces (splines) of a CAD part: "panel" (one NURBS) or "folded" (two faces)."""
    from georeg_plugin.spline.geometries import cylinder, quadrilateral, transformed
    p = CAD_PARTS
    if part == "panel":
        length, width = p["panel_mm"]
        angle = 2 * np.degrees(np.arcsin(0.5 * width / p["radius_mm"]))
        return [transformed(cylinder(p["radius_mm"], length, angle, axis="x"),
                            translation=(0.0, 0.0, -p["radius_mm"]))]
    half, width = 0.5 * p["folded_mm"][0], p["folded_mm"][1]
    z = -p["slope"] * half
    w = 0.5 * width
    return [quadrilateral([[-half, -w, z], [0, -w, 0], [0, w, 0], [-half, w, z]]),
            quadrilateral([[0, -w, 0], [half, -w, z], [half, w, z], [0, w, 0]])]


def cad_scene(part: str) -> Scene:
    """The rendered part ("panel" or "folded", see ``CAD_PARTS``) with its truth."""
    p = CAD_PARTS
    cameras = demo_cameras(image_size=(480, 320), field_mm=72.0)
    if part == "panel":
        args = dict(radius=p["true_radius_mm"], wave=p["wave_mm"], length=p["panel_mm"][0])
        height, gradient, size = _panel_height, _panel_gradient, p["panel_mm"]
    else:
        args = dict(slope=p["true_slope"], bow=p["bow_mm"], width=p["folded_mm"][1])
        height, gradient, size = _folded_height, _folded_gradient, p["folded_mm"]
    specimen = Specimen(*size, height=functools.partial(height, **args),
                        height_gradient=functools.partial(gradient, **args),
                        speckle_mm=speckle_mm_for(cameras[0], 4.0), seed=9)
    arrays = render_stereo(specimen, cameras, supersample=3, noise_std=2.0, seed=12, progress=False)
    return Scene(specimen, tuple(cameras), tuple(arrays))


#: the displacement tests' plate and rig (tests/fesdic_core/displacement/test_displacement.py:
#: 60 x 40 mm, 320 x 240 px over 72 mm, 4 px speckle, 2 gray levels of noise), then the same
#: paint on the plate twisted by 1 mm at its corners and wavy (0.2 mm), rendered independently
#: (benchmarks/bench_validity.py's ``twist`` pair)
TWIST_WAVE = dict(image_size=(320, 240), field_mm=72.0, plate_mm=(60.0, 40.0), corner_mm=1.0,
                  waviness_mm=0.2, noise_std=2.0, seed=3)


class TwistPair:
    """A flat plate, then the same paint twisted and wavy (:data:`TWIST_WAVE`); each pair is
    rendered on first use (about 2 s each)."""

    def __init__(self):
        from fesdic_core.synthetic.motion import HeightMotion
        from fesdic_core.synthetic.specimen import flat_plate
        d = TWIST_WAVE
        self.cameras = tuple(demo_cameras(image_size=d["image_size"], field_mm=d["field_mm"]))
        speckle = speckle_mm_for(self.cameras[0], 4.0)
        self.flat = flat_plate(*d["plate_mm"], speckle_mm=speckle, seed=d["seed"])
        self.twisted = twisted_plate(*d["plate_mm"], corner_mm=d["corner_mm"],
                                     waviness_mm=d["waviness_mm"], speckle_mm=speckle,
                                     seed=d["seed"])
        self.motion = HeightMotion(self.twisted.height)    # u (n, 3) of the reference points

    def _pair(self, specimen, seed, tag, motion=None):
        arrays = render_stereo(specimen, self.cameras, supersample=3,
                               noise_std=TWIST_WAVE["noise_std"], seed=seed, progress=False,
                               motion=motion)
        return tuple(Image.from_array(a, source=f"{tag} cam{k}") for k, a in enumerate(arrays))

    @functools.cached_property
    def reference(self) -> tuple:
        """The flat plate's pair."""
        return self._pair(self.flat, 1, "flat")

    @functools.cached_property
    def deformed(self) -> tuple:
        """The twisted and wavy plate's pair."""
        return self._pair(self.twisted, 2, "twisted")

    def moved(self, motion, seed: int = 3) -> tuple:
        """The flat plate's pair under another ``motion`` (rendered at each call)."""
        return self._pair(self.flat, seed, "moved", motion)


def twist_wave_pair() -> TwistPair:
    return TwistPair()
