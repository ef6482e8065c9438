"""The measurement data model: measurements, samples and the measurement set of one pigment.

A :class:`MeasurementSet` holds everything measured on the samples of one
pigment at a common set of wavelengths: each :class:`Sample` is a paint film, a
bare substrate, a clear-coated substrate or a film on glass, with the list of
:class:`Measurement` s made on it (BRDF at geometries, hemispherical SCI/SCE,
45°/0°, specular transmittance). A film's substrate is a constant albedo seen
from the binder (``r_s``), the paper's ``"black"`` (0.01) or ``"white"`` (0.95)
(section 4.1), or the name of a bare-substrate sample of the set, from whose
measurement in air ``r_s(λ)`` is derived as in section 3.4 (eq. 9 inverted).
Films that share thickness and pigment concentration share ``tau``: they carry
the same ``film_group`` (the same drawdown over black and over white).

Everything is validated on construction; problems raise
:class:`~bayespig.data.errors.MeasurementError`.

Values are fractions: BRDF in 1/sr (without the surface's specular
reflection), reflectances and transmittances in [0, 1].
"""

from __future__ import annotations

import functools
import json
import math
import re
import types
import unicodedata
from dataclasses import dataclass, field

import numpy as np

from ..instruments import Channel, Instrument
from ..physics.geometry import parse_geometry_label
from ..physics.substrate import substrate_albedo_from_air
from .errors import MeasurementError, Problem
from .writers import write_astm_e1392, write_csv

__all__ = [
    "BLACK_SUBSTRATE_ALBEDO",
    "BRDF_MAX",
    "FILM_ROLES",
    "MEASUREMENT_KINDS",
    "METHODS",
    "PERCENT_THRESHOLD",
    "REFLECTANCE_KINDS",
    "REFLECTANCE_MAX",
    "ROLES",
    "SUBSTRATE_ROLES",
    "WAVELENGTH_RANGE_NM",
    "WHITE_SUBSTRATE_ALBEDO",
    "Measurement",
    "MeasurementSet",
    "MethodSupport",
    "Sample",
    "parse_measurement_geometry",
]

#: Sample roles.
ROLES = ("film", "substrate", "clear_coated_substrate", "film_on_glass")
#: Roles whose samples are substrates (measured from air; ``r_s`` derived by eq. 9 inverted).
SUBSTRATE_ROLES = ("substrate", "clear_coated_substrate")
#: Roles whose samples are paint films.
FILM_ROLES = ("film", "film_on_glass")
#: What can be measured on a sample.
MEASUREMENT_KINDS = ("brdf", "hemispherical", "reflectance_factor", "specular_transmittance")
#: Measurement kinds that are reflectances (modelled by :func:`bayespig.instruments.predict`).
REFLECTANCE_KINDS = ("brdf", "hemispherical", "reflectance_factor")
#: The paper's four extraction methods (section 3).
METHODS = ("method1", "method2", "method3", "method4")
#: Albedo from the binder of a black substrate, paper section 4.1 [-].
BLACK_SUBSTRATE_ALBEDO = 0.01
#: Albedo from the binder of a white substrate, paper section 4.1 [-].
WHITE_SUBSTRATE_ALBEDO = 0.95
#: A reflectance or transmittance above this is taken for a value in percent [-].
PERCENT_THRESHOLD = 1.5
#: Largest hemispherical reflectance or specular transmittance accepted [-]. A passive,
#: non-fluorescent sample cannot send back more light than it receives (1); 0.05 above that
#: allows for the calibration error of the white standard (tiles are certified to ~1 %) and
#: for noise. More than this is not a measurement error but a wrong calibration, percent
#: values in a fraction column, or fluorescence, which the model does not describe. The file
#: readers apply it; a :class:`Measurement` built in Python (a simulation with noise, eq. 7,
#: may exceed it) is only refused above :data:`PERCENT_THRESHOLD`.
REFLECTANCE_MAX = 1.05
#: Largest BRDF accepted [1/sr]. The BRDF of a perfect mirror seen by a detector of solid
#: angle Omega is about 1 / Omega: 1e4 1/sr is a mirror through an aperture of 1e-4 sr (a cone
#: of 0.32 deg half-angle), beyond the sharpest gonio-spectrophotometers; bayespig's BRDFs
#: exclude the surface's mirror reflection, and the near-mirror peaks of the Cornell
#: measurements reach 66 1/sr.
BRDF_MAX = 1e4
#: Wavelengths accepted [nm]: the range of UV-visible-NIR spectrophotometers (e.g. 175-3300 nm
#: for a PerkinElmer Lambda 1050). Wavelengths in micrometres (0.4-0.7) or angstroms
#: (4000-7000) fall outside it and are named as such.
WAVELENGTH_RANGE_NM = (170.0, 3300.0)
#: Angles are rounded to this many decimals of a degree when parsed.
ANGLE_DECIMALS = 6
#: Sample names shown by ``repr`` of a measurement set.
REPR_SAMPLES = 8

_NAMED_SUBSTRATES = {"black": BLACK_SUBSTRATE_ALBEDO, "white": WHITE_SUBSTRATE_ALBEDO}
_HEMISPHERICAL = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*d\s*[-_ ]?\s*(sci|sce)\s*$", re.IGNORECASE)
_REFLECTANCE_FACTOR = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*[-/]\s*(\d+(?:\.\d+)?)\s*$")
_TRIPLE = re.compile(
    r"^\s*([-+]?\d+(?:\.\d+)?)\s*/\s*([-+]?\d+(?:\.\d+)?)\s*/\s*([-+]?\d+(?:\.\d+)?)\s*$"
)


def _fmt_angle(x):
    """Decimal text of an angle without exponent or trailing zeros (``45``, ``12.5``)."""
    text = f"{x:.{ANGLE_DECIMALS}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _round_angle(x):
    value = round(float(x), ANGLE_DECIMALS)
    return 0.0 if value == 0.0 else value


def _check_brdf_angles(theta_i, theta_o, delta_phi):
    for name, value in (("theta_i", theta_i), ("theta_o", theta_o)):
        if not 0.0 <= value < 90.0:
            raise ValueError(f"{name} = {value:g} deg is outside [0, 90)")
    if not 0.0 <= delta_phi <= 180.0:
        raise ValueError(f"delta_phi = {delta_phi:g} deg is outside [0, 180]")
    if theta_o == 0.0 or theta_i == 0.0:
        delta_phi = 180.0  # the azimuth is undefined along the normal
    if theta_i == theta_o and delta_phi == 180.0:
        raise ValueError(
            f"{_fmt_angle(theta_i)}/{_fmt_angle(theta_o)}/180 is the specular direction "
            "(aspecular 0), "
            "where the model has no value (the BRDF excludes the surface's mirror reflection); "
            "remove this geometry"
        )
    return theta_i, theta_o, delta_phi


def brdf_label(theta_i, theta_o, delta_phi):
    """Canonical label of a BRDF geometry: the ASTM E2194 label in the plane of incidence.

    ``"45as15"`` when ``delta_phi`` is 0 or 180 [deg], else ``"theta_i/theta_o/delta_phi"``.
    """
    if delta_phi == 180.0:
        return f"{_fmt_angle(theta_i)}as{_fmt_angle(_round_angle(theta_i - theta_o))}"
    if delta_phi == 0.0:
        return f"{_fmt_angle(theta_i)}as{_fmt_angle(_round_angle(theta_i + theta_o))}"
    return f"{_fmt_angle(theta_i)}/{_fmt_angle(theta_o)}/{_fmt_angle(delta_phi)}"


def parse_measurement_geometry(kind, text):
    """Angles of a measurement from its kind and geometry text.

    Parameters
    ----------
    kind : str
        One of :data:`MEASUREMENT_KINDS`.
    text : str
        ``brdf``: an ASTM E2194 label (``"45as-15"``, ``"45as110"``) or
        ``"theta_i/theta_o/delta_phi"`` [deg] (``delta_phi = 180`` on the specular
        side); ``hemispherical``: ``"8d-sci"`` or ``"8d-sce"`` (incidence angle,
        specular component included or excluded); ``reflectance_factor``:
        ``"45-0"`` (illumination–viewing angles [deg]); ``specular_transmittance``:
        ``"normal"``, ``"0"`` or empty (normal incidence, eq. 5).

    Returns
    -------
    dict
        ``theta_i``, ``theta_o``, ``delta_phi`` [deg], ``specular`` (``"included"``,
        ``"excluded"`` or None) and the canonical ``label``.

    Raises
    ------
    ValueError
        When the text does not parse, an angle is out of range, or a BRDF
        geometry is the specular direction.
    """
    text = "" if text is None else str(text).strip()
    return dict(_parse_measurement_geometry(kind, text))


@functools.lru_cache(maxsize=4096)
def _parse_measurement_geometry(kind, text):
    """:func:`parse_measurement_geometry` of stripped text (cached)."""
    text = "" if text is None else str(text).strip()
    if kind == "brdf":
        triple = _TRIPLE.match(text)
        if triple:
            theta_i, theta_o, delta_phi = (_round_angle(v) for v in triple.groups())
        else:
            if not text:
                raise ValueError("a BRDF needs a geometry such as '45as15' or '45/30/180'")
            try:
                theta_i, theta_o, delta_phi = (_round_angle(v) for v in parse_geometry_label(text))
            except ValueError as error:
                if "form" in str(error):
                    raise ValueError(
                        f"BRDF geometry {text!r} is neither an ASTM E2194 label such as '45as15' "
                        "nor 'theta_i/theta_o/delta_phi' such as '45/30/180'"
                    ) from None
                hint = (
                    "; remove this geometry: the model has no value at the mirror direction"
                    if "specular direction" in str(error)
                    else ""
                )
                raise ValueError(f"geometry {text!r}: {error}{hint}") from None
        theta_i, theta_o, delta_phi = _check_brdf_angles(theta_i, theta_o, delta_phi)
        return dict(
            theta_i=theta_i,
            theta_o=theta_o,
            delta_phi=delta_phi,
            specular=None,
            label=brdf_label(theta_i, theta_o, delta_phi),
        )
    if kind == "hemispherical":
        match = _HEMISPHERICAL.match(text)
        if not match:
            raise ValueError(
                f"hemispherical geometry {text!r} must be '<incidence>d-sci' or "
                "'<incidence>d-sce', e.g. '8d-sci' (specular component included) or '8d-sce'"
            )
        theta_i = _round_angle(match.group(1))
        if not theta_i < 90.0:
            raise ValueError(f"incidence angle {theta_i:g} deg is outside [0, 90)")
        specular = "included" if match.group(2).lower() == "sci" else "excluded"
        return dict(
            theta_i=theta_i,
            theta_o=theta_i,
            delta_phi=0.0,
            specular=specular,
            label=f"{_fmt_angle(theta_i)}d-{match.group(2).lower()}",
        )
    if kind == "reflectance_factor":
        match = _REFLECTANCE_FACTOR.match(text)
        if not match:
            raise ValueError(
                f"45/0 geometry {text!r} must be '<illumination>-<viewing>', e.g. '45-0'"
            )
        theta_i, theta_o = (_round_angle(v) for v in match.groups())
        theta_i, theta_o, delta_phi = _check_brdf_angles(theta_i, theta_o, 180.0)
        return dict(
            theta_i=theta_i,
            theta_o=theta_o,
            delta_phi=delta_phi,
            specular=None,
            label=f"{_fmt_angle(theta_i)}-{_fmt_angle(theta_o)}",
        )
    if kind == "specular_transmittance":
        if text.lower() not in ("", "0", "normal"):
            raise ValueError(
                f"specular transmittance is measured at normal incidence: geometry must be "
                f"'normal' (or empty), got {text!r}"
            )
        return dict(theta_i=0.0, theta_o=0.0, delta_phi=180.0, specular=None, label="normal")
    raise ValueError(f"measurement must be one of {', '.join(MEASUREMENT_KINDS)}, got {kind!r}")


def wavelength_problem(wavelength_nm):
    """Why wavelengths cannot be nanometres (guessing their unit), or None when they can.

    Parameters
    ----------
    wavelength_nm : array_like
        Finite wavelengths [nm].

    Returns
    -------
    tuple (int, str) or None
        Index of the first wavelength outside :data:`WAVELENGTH_RANGE_NM`, and the message.
    """
    wavelength = np.asarray(wavelength_nm, dtype=float)
    low, high = WAVELENGTH_RANGE_NM
    outside = np.flatnonzero((wavelength < low) | (wavelength > high))
    if wavelength.size == 0 or outside.size == 0:
        return None
    first, last = wavelength.min(), wavelength.max()
    span = f"{first:.10g}–{last:.10g}" if first != last else f"{first:.10g}"
    if low / 1000 <= first and last <= high / 1000:
        unit, fix = "micrometres", "multiply them by 1000"
    elif low * 10 <= first and last <= high * 10:
        unit, fix = "ångströms", "divide them by 10"
    else:
        value = wavelength[outside[0]]
        return int(outside[0]), (
            f"wavelength {value:.10g} nm is outside {low:g}–{high:g} nm, the range of UV–visible–NIR "
            "spectrophotometers; give wavelengths in nanometres"
        )
    return int(outside[0]), (
        f"wavelengths {span} look like {unit}; bayespig wants nanometres ({fix})"
    )


def value_problem(kind, values, *, percent=False, reflectance_max=REFLECTANCE_MAX):
    """The first value no instrument can report for a measurement ``kind``, or None.

    Parameters
    ----------
    kind : str
        Measurement kind.
    values : numpy.ndarray
        Finite, non-negative fractions (BRDF in 1/sr).
    percent : bool
        Write reflectances in the message in percent (as the file gave them).
    reflectance_max : float
        Bound of hemispherical reflectances and specular transmittances [-]:
        :data:`REFLECTANCE_MAX` for measured files; :class:`Measurement` itself
        uses :data:`PERCENT_THRESHOLD`, since simulated values with noise (eq. 7)
        may exceed 1.05.

    Returns
    -------
    tuple (int, str) or None
        Index of the largest offending value and a message naming the bound
        (:data:`BRDF_MAX` for BRDFs, :data:`REFLECTANCE_MAX` for hemispherical
        reflectances and specular transmittances, :data:`PERCENT_THRESHOLD` for
        45°/0° reflectance factors).
    """
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return None
    top = int(np.argmax(values))
    value = values[top]

    def text(x):
        return f"{x * 100:g} %" if percent else f"{x:g}"

    if kind == "brdf":
        if value > BRDF_MAX:
            return top, (
                f"BRDF {value:g} 1/sr exceeds {BRDF_MAX:g} 1/sr, more than any "
                "gonio-spectrophotometer reports (a mirror seen through a 0.3° aperture); "
                "check the units (BRDF in 1/sr)"
            )
        return None
    if kind == "reflectance_factor":
        if value > PERCENT_THRESHOLD:
            return top, (
                f"reflectance factor {text(value)} exceeds {text(PERCENT_THRESHOLD)}: this looks "
                "like percent; divide by 100"
            )
        return None
    if value > reflectance_max:
        what = "transmittance" if kind == "specular_transmittance" else "reflectance"
        if value > PERCENT_THRESHOLD and not percent:
            return top, (
                f"{what} {text(value)} exceeds {text(PERCENT_THRESHOLD)}: this looks like "
                "percent; divide by 100"
            )
        verb = "transmits" if kind == "specular_transmittance" else "reflects"
        return top, (
            f"{what} {text(value)} exceeds {text(REFLECTANCE_MAX)}: no sample {verb} more light "
            "than it receives (above 1 only by the calibration error of the white standard, a "
            "few %); check the instrument's calibration"
        )
    return None


def _control_character(text):
    """The first control character (NUL, tab, CR, LF, ...; Unicode category Cc) of ``text``."""
    return next((c for c in text if unicodedata.category(c) == "Cc"), None)


def _error(message, field=None, sample=None, measurement=None):
    return MeasurementError(Problem(message, field=field, sample=sample, measurement=measurement))


def _readonly_values(values, what):
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise _error(f"{what} must be numbers", field="values") from None
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Measurement:
    """One measured spectrum of one sample at one geometry.

    Construct with :meth:`from_geometry` (from a geometry label) or
    :meth:`from_channel` (from an instrument channel).

    Attributes
    ----------
    kind : {"brdf", "hemispherical", "reflectance_factor", "specular_transmittance"}
        BRDF [1/sr]; directional–hemispherical reflectance [-] (SCI/SCE);
        45°/0° reflectance factor (``pi * BRDF``) [-]; specular transmittance at
        normal incidence (eq. 5) [-].
    label : str
        Canonical geometry label (``"45as15"``, ``"8d-sci"``, ``"45-0"``, ``"normal"``).
    theta_i, theta_o, delta_phi : float
        Incidence and viewing angles in air and their azimuth difference [deg]
        (``delta_phi = 180`` on the specular side).
    specular : {"included", "excluded"} or None
        For hemispherical measurements, SCI or SCE.
    values : numpy.ndarray
        Shape (n_wavelengths,), fractions (read-only).
    source : tuple of (str, int) or None
        The file and 1-based line the values were read from, for messages (None
        when not read from a file); not part of equality.
    """

    kind: str
    label: str
    theta_i: float
    theta_o: float
    delta_phi: float
    specular: str | None
    values: np.ndarray
    source: tuple | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        try:
            expected = parse_measurement_geometry(self.kind, self.label)
        except ValueError as error:
            raise _error(
                str(error), field="geometry" if self.kind in MEASUREMENT_KINDS else "measurement"
            ) from None
        for name in ("theta_i", "theta_o", "delta_phi", "specular"):
            if getattr(self, name) != expected[name]:
                raise _error(
                    f"{name} = {getattr(self, name)!r} does not match geometry {self.label!r} "
                    f"(expected {expected[name]!r}); build measurements with "
                    "Measurement.from_geometry",
                    field="geometry",
                )
        values = _readonly_values(self.values, f"values of {self.label}")
        if values.ndim != 1 or values.size == 0:
            raise _error(
                f"values of {self.label} must be a 1-D spectrum, got shape {values.shape}",
                field="values",
            )
        if np.isnan(values).any():
            raise _error(f"values of {self.label} contain NaN", field="values")
        if not np.isfinite(values).all():
            raise _error(f"values of {self.label} contain infinite numbers", field="values")
        if (values < 0).any():
            raise _error(
                f"values of {self.label} are negative (min {values.min():.4g})", field="values"
            )
        bad = value_problem(self.kind, values, reflectance_max=PERCENT_THRESHOLD)
        if bad is not None:
            raise _error(f"values of {self.label}: {bad[1]}", field="values")
        object.__setattr__(self, "label", expected["label"])
        object.__setattr__(self, "values", values)

    @classmethod
    def from_geometry(cls, kind, geometry, values, source=None):
        """A measurement from kind, geometry and values (:func:`parse_measurement_geometry`)."""
        try:
            angles = parse_measurement_geometry(kind, geometry)
        except ValueError as error:
            raise _error(
                str(error), field="measurement" if kind not in MEASUREMENT_KINDS else "geometry"
            ) from None
        return cls(
            kind,
            angles["label"],
            angles["theta_i"],
            angles["theta_o"],
            angles["delta_phi"],
            angles["specular"],
            values,
            source,
        )

    @classmethod
    def from_channel(cls, channel, values):
        """A measurement at an instrument :class:`~bayespig.instruments.Channel`."""
        if channel.kind == "hemispherical":
            sphere = "sci" if channel.specular == "included" else "sce"
            geometry = f"{_fmt_angle(channel.theta_i)}d-{sphere}"
        elif channel.kind == "reflectance_factor":
            geometry = f"{_fmt_angle(channel.theta_i)}-{_fmt_angle(channel.theta_o)}"
        else:
            angles = (channel.theta_i, channel.theta_o, channel.delta_phi)
            geometry = "/".join(_fmt_angle(x) for x in angles)
        return cls.from_geometry(channel.kind, geometry, values)

    @property
    def geometry_key(self):
        """What makes two measurements of a sample the same: kind and angles."""
        return (self.kind, self.theta_i, self.theta_o, self.delta_phi, self.specular)

    @property
    def channel(self):
        """This measurement's :class:`~bayespig.instruments.Channel` (None for transmittance)."""
        if self.kind == "specular_transmittance":
            return None
        return Channel(
            self.kind, self.theta_i, self.theta_o, self.delta_phi, self.specular, self.label
        )

    def __eq__(self, other):
        if not isinstance(other, Measurement):
            return NotImplemented
        return (
            self.geometry_key == other.geometry_key
            and self.label == other.label
            and self.values.shape == other.values.shape
            and np.array_equal(self.values, other.values)
        )

    __hash__ = None


def _optional_positive(value, name, sample):
    if value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise _error(f"{name} must be a number, got {value!r}", field=name, sample=sample) from None
    if not math.isfinite(number) or number <= 0:
        raise _error(
            f"{name} must be a finite number > 0, got {value!r}", field=name, sample=sample
        )
    return number


@dataclass(frozen=True)
class Sample:
    """One physical sample and what was measured on it.

    Attributes
    ----------
    name : str
        Unique within a set.
    role : {"film", "substrate", "clear_coated_substrate", "film_on_glass"}
        A paint film on a substrate; a bare substrate (card) measured from air;
        a substrate under a clear binder layer; a paint film on glass (for the
        specular transmittance of method 1).
    measurements : tuple of Measurement
        At least one; no geometry twice.
    substrate : float, str or None
        For films: an albedo from the binder in [0, 1], ``"black"`` (0.01),
        ``"white"`` (0.95), or the name of a substrate sample of the set. Not
        needed for opaque films nor for a film on glass measured only in
        transmission. Must be None for substrate samples.
    film_group : str or None
        Films with the same group share thickness and concentration, hence
        ``tau``. None means a group of its own (named like the sample).
    opaque : bool
        The film hides its substrate: ``tau = inf`` (eq. 2).
    thickness_um : float or None
        Dry film thickness [µm] (turns ``tau`` into ``k_ext``).
    concentration : float or None
        Pigment concentration ``D`` up to a constant scale (appendix A2) [arbitrary units].
    eps : float or None
        Known relative error of the measured values (eq. 7) [-].
    """

    name: str
    role: str
    measurements: tuple
    substrate: float | str | None = None
    film_group: str | None = None
    opaque: bool = False
    thickness_um: float | None = None
    concentration: float | None = None
    eps: float | None = None

    def __post_init__(self):
        name = self.name
        if not isinstance(name, str) or not name.strip() or name != name.strip():
            raise _error(
                f"sample name must be non-empty text without surrounding blanks, got {name!r}",
                field="sample",
                sample=str(name),
            )
        control = _control_character(name)
        if control:
            raise _error(
                f"sample name {name!r} contains the control character {control!r}, which no "
                "measurement file can hold; rename the sample",
                field="sample",
                sample=name,
            )
        if self.role not in ROLES:
            raise _error(
                f"role must be one of {', '.join(ROLES)}, got {self.role!r}",
                field="role",
                sample=name,
            )
        measurements = tuple(self.measurements)
        if not measurements:
            raise _error(
                "a sample needs at least one measurement", field="measurement", sample=name
            )
        seen = {}
        for index, m in enumerate(measurements):
            if not isinstance(m, Measurement):
                raise _error(
                    f"measurements must be Measurement objects, got {type(m).__name__}",
                    field="measurement",
                    sample=name,
                )
            if m.geometry_key in seen:
                raise _error(
                    f"{m.kind} at {m.label} is given twice (measurements "
                    f"{seen[m.geometry_key] + 1} "
                    f"and {index + 1}); remove the duplicate",
                    field="geometry",
                    sample=name,
                    measurement=index,
                )
            seen[m.geometry_key] = index
        object.__setattr__(self, "measurements", measurements)
        if not isinstance(self.opaque, (bool, np.bool_)):
            raise _error(
                f"opaque must be True or False, got {self.opaque!r}", field="opaque", sample=name
            )
        object.__setattr__(self, "opaque", bool(self.opaque))
        for attribute in ("thickness_um", "concentration", "eps"):
            object.__setattr__(
                self, attribute, _optional_positive(getattr(self, attribute), attribute, name)
            )
        if self.film_group is not None and (
            not isinstance(self.film_group, str)
            or not self.film_group.strip()
            or _control_character(self.film_group)
        ):
            raise _error(
                "film_group must be non-empty text without control characters or None, got "
                f"{self.film_group!r}",
                field="film_group",
                sample=name,
            )
        self._check_substrate()
        self._check_role()

    def _check_substrate(self):
        substrate = self.substrate
        if isinstance(substrate, (bool, np.bool_)):
            raise _error(
                f"substrate must be a number, a name or None, got {substrate!r}",
                field="substrate",
                sample=self.name,
            )
        if substrate is None or isinstance(substrate, str):
            if isinstance(substrate, str) and not substrate.strip():
                raise _error(
                    "substrate must not be empty text", field="substrate", sample=self.name
                )
            return
        try:
            value = float(substrate)
        except (TypeError, ValueError):
            raise _error(
                f"substrate must be a number, a name or None, got {substrate!r}",
                field="substrate",
                sample=self.name,
            ) from None
        if not 0.0 <= value <= 1.0:
            raise _error(
                f"substrate albedo {value!r} is outside [0, 1]", field="substrate", sample=self.name
            )
        object.__setattr__(self, "substrate", value)

    def _check_role(self):
        name, kinds = self.name, [m.kind for m in self.measurements]
        if self.role in SUBSTRATE_ROLES:
            for attribute, default in (
                ("substrate", None),
                ("film_group", None),
                ("opaque", False),
                ("thickness_um", None),
                ("concentration", None),
            ):
                if getattr(self, attribute) != default:
                    raise _error(
                        f"a {self.role} sample has no {attribute} (it is not a paint film)",
                        field=attribute,
                        sample=name,
                    )
        if "specular_transmittance" in kinds and self.role != "film_on_glass":
            raise _error(
                "specular transmittance is measured on a film on glass: set role to "
                "'film_on_glass'",
                field="role",
                sample=name,
            )
        if self.role == "film_on_glass" and self.opaque:
            raise _error(
                "a film on glass for specular transmittance cannot be opaque",
                field="opaque",
                sample=name,
            )
        needs_substrate = (
            self.role in FILM_ROLES and not self.opaque and bool(self.reflectance_measurements)
        )
        if needs_substrate and self.substrate is None:
            raise _error(
                "this film is not opaque and has reflectance measurements, so it needs a "
                "substrate: "
                "'black' (r_s = 0.01), 'white' (0.95), an albedo in [0, 1], or the name of a "
                "substrate sample; or mark it opaque",
                field="substrate",
                sample=name,
            )

    @property
    def group(self):
        """The film group (the sample name when none is given)."""
        return self.film_group if self.film_group is not None else self.name

    @property
    def reflectance_measurements(self):
        """The measurements that are reflectances (BRDF, hemispherical, 45°/0°)."""
        return tuple(m for m in self.measurements if m.kind in REFLECTANCE_KINDS)

    @property
    def transmittance(self):
        """The specular-transmittance measurement, or None."""
        found = [m for m in self.measurements if m.kind == "specular_transmittance"]
        return found[0] if found else None

    @property
    def channels(self):
        """Instrument channels of the reflectance measurements, in order."""
        return tuple(m.channel for m in self.reflectance_measurements)

    def instrument(self, n=1.45):
        """An :class:`~bayespig.instruments.Instrument` of this sample's reflectance channels."""
        if not self.reflectance_measurements:
            raise ValueError(f"sample {self.name!r} has no reflectance measurements")
        return Instrument(f"sample:{self.name}", self.channels, n)

    @property
    def reflectance(self):
        """Reflectance values, shape (n_wavelengths, n_channels), ordered as :attr:`channels`."""
        return np.stack([m.values for m in self.reflectance_measurements], axis=-1)


@dataclass(frozen=True)
class MethodSupport:
    """Whether a measurement set can serve one of the paper's methods, and with which samples.

    Attributes
    ----------
    method : str
    supported : bool
    samples : tuple of str
        The samples that serve the method (empty when unsupported).
    reason : str
        What serves it, or what is missing.
    """

    method: str
    supported: bool
    samples: tuple
    reason: str

    def __bool__(self):
        return self.supported


def _jsonable(value, path="metadata"):
    """A JSON-native deep copy (dict/list/str/int/float/bool/None) of metadata, or ValueError."""
    if isinstance(value, (str, bool)) or value is None:
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist(), path)
    if isinstance(value, (list, tuple)):
        return [_jsonable(v, f"{path}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, (dict, types.MappingProxyType)):
        out = {}
        for key, v in value.items():
            if not isinstance(key, str):
                raise ValueError(f"{path} keys must be text, got {key!r}")
            out[key] = _jsonable(v, f"{path}[{key!r}]")
        return out
    raise ValueError(
        f"{path} must hold only text, numbers, lists and dicts (JSON), got {type(value).__name__}"
    )


@dataclass(frozen=True, eq=False)
class MeasurementSet:
    """Everything measured on the samples of one pigment, at common wavelengths.

    Parameters
    ----------
    wavelength_nm : array_like
        Shape (n_wavelengths,), strictly increasing [nm].
    samples : sequence of Sample
        Unique names; every measurement has n_wavelengths values.
    n : float
        Refractive index of the binder [-] (for substrate albedos from air and the model).
    metadata : dict
        JSON-like data (text, numbers, lists, dicts): provenance, simulation truth,
        composition. Stored as a read-only mapping.
    source : str or None
        The file it was read from (not part of equality).

    Raises
    ------
    MeasurementError
        Listing every problem: wavelengths, lengths, names, substrates, film groups.
    """

    wavelength_nm: np.ndarray
    samples: tuple
    n: float = 1.45
    metadata: dict = field(default_factory=dict)
    source: str | None = None

    def __post_init__(self):
        problems = []
        wavelength = np.array(self.wavelength_nm, dtype=float)
        if wavelength.ndim != 1 or wavelength.size == 0:
            problems.append(
                Problem(
                    f"wavelength_nm must be a non-empty 1-D array, got shape {wavelength.shape}",
                    field="wavelength_nm",
                )
            )
        elif not np.isfinite(wavelength).all() or (wavelength <= 0).any():
            problems.append(Problem("wavelengths must be finite and > 0 nm", field="wavelength_nm"))
        elif (np.diff(wavelength) <= 0).any():
            problems.append(
                Problem(
                    "wavelengths must be strictly increasing (no duplicates)", field="wavelength_nm"
                )
            )
        wavelength.flags.writeable = False
        object.__setattr__(self, "wavelength_nm", wavelength)
        samples = tuple(self.samples)
        object.__setattr__(self, "samples", samples)
        try:
            n = float(self.n)
        except (TypeError, ValueError):
            n = float("nan")
        if not math.isfinite(n) or n < 1.0:
            problems.append(
                Problem(
                    f"binder refractive index n must be a number >= 1, got {self.n!r}", field="n"
                )
            )
        object.__setattr__(self, "n", n)
        try:
            metadata = _jsonable(dict(self.metadata))
        except (TypeError, ValueError) as error:
            problems.append(Problem(str(error), field="metadata"))
            metadata = {}
        object.__setattr__(self, "metadata", types.MappingProxyType(metadata))
        if not problems:
            problems = set_problems(wavelength, samples)
        if problems:
            raise MeasurementError(problems).located(self.source)

    def __reduce__(self):
        """Pickle by the constructor's arguments (the read-only metadata as a dict), so a set can
        be sent to a worker process as it is and is checked again when it arrives."""
        return (type(self), (self.wavelength_nm, self.samples, self.n, dict(self.metadata), self.source))

    # ------------------------------------------------------------------ access
    @property
    def n_wavelengths(self):
        """Number of wavelengths."""
        return self.wavelength_nm.size

    @property
    def sample_names(self):
        """Names of the samples, in order."""
        return tuple(s.name for s in self.samples)

    def _index(self):
        """Name -> sample (built once: the samples of a frozen set never change)."""
        index = self.__dict__.get("_by_name")
        if index is None:
            index = {}
            for sample in reversed(self.samples):
                index[getattr(sample, "name", None)] = sample
            object.__setattr__(self, "_by_name", index)
        return index

    def has_sample(self, name):
        """True when a sample is called ``name`` (constant time)."""
        return name in self._index()

    def sample(self, name):
        """The sample called ``name``."""
        index = self._index()
        if name in index:
            return index[name]
        raise KeyError(f"no sample {name!r}; samples: {', '.join(self.sample_names)}")

    @property
    def films(self):
        """Samples with a film role."""
        return tuple(s for s in self.samples if s.role in FILM_ROLES)

    @property
    def substrates(self):
        """Samples with a substrate role."""
        return tuple(s for s in self.samples if s.role in SUBSTRATE_ROLES)

    @property
    def film_groups(self):
        """Film group -> tuple of its films (films in one group share ``tau``)."""
        groups = {}
        for film in self.films:
            groups.setdefault(film.group, []).append(film)
        return {group: tuple(films) for group, films in groups.items()}

    # ------------------------------------------------------------- substrates
    def substrate_albedo(self, sample):
        """Albedo of a film's substrate seen from the binder, ``r_s(λ)``.

        A constant or ``"black"``/``"white"`` (0.01/0.95, paper section 4.1) is
        broadcast over the wavelengths. A substrate sample measured from air is
        converted by inverting eq. (9) (a Lambertian surface under clear binder,
        section 3.4; :func:`bayespig.physics.substrate.substrate_albedo_from_air`)
        for each of its measurements, and the results are averaged over its
        geometries. A sample name takes precedence over ``"black"``/``"white"``.

        Parameters
        ----------
        sample : str or Sample
            A film of this set.

        Returns
        -------
        numpy.ndarray
            ``r_s``, shape (n_wavelengths,) [-]. Zeros for an opaque film (the
            substrate is hidden).

        Raises
        ------
        MeasurementError
            When the substrate measurement cannot come from a Lambertian
            substrate under binder (too bright, or darker than the surface
            reflection alone for SCI).
        """
        film = self.sample(sample) if isinstance(sample, str) else sample
        if film.role not in FILM_ROLES:
            raise ValueError(f"sample {film.name!r} is a {film.role}, not a film")
        if film.opaque or film.substrate is None:
            return np.zeros(self.n_wavelengths)
        if isinstance(film.substrate, float):
            return np.full(self.n_wavelengths, film.substrate)
        if self.has_sample(film.substrate):
            return _albedo_from_air(self.sample(film.substrate), self.n)
        return np.full(self.n_wavelengths, _NAMED_SUBSTRATES[film.substrate])

    # ---------------------------------------------------------------- methods
    def supported_methods(self):
        """Which of the paper's methods 1–4 the samples can serve.

        Returns
        -------
        dict
            ``"method1"`` … ``"method4"`` -> :class:`MethodSupport` (true when
            supported, with the samples that serve it; otherwise the reason,
            naming what is missing).
        """
        return {method: _method_support(self, method) for method in METHODS}

    def require_method(self, method):
        """The samples serving ``method``; :class:`MeasurementError` saying what is missing."""
        if method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
        support = _method_support(self, method)
        if not support:
            raise MeasurementError(Problem(support.reason, file=self.source, field="method"))
        return support.samples

    def for_method(self, method):
        """The subset of samples (with their substrate samples) that serves ``method``."""
        return self.select(self.require_method(method))

    # -------------------------------------------------------------- selection
    def select(self, names=None, *, roles=None):
        """A new set with some samples (and the substrate samples their films refer to).

        Parameters
        ----------
        names : iterable of str, optional
            Sample names to keep (default: all).
        roles : iterable of str, optional
            Keep only samples with these roles (substrates referred to by kept
            films are kept regardless).
        """
        keep = set(self.sample_names if names is None else names)
        unknown = keep - set(self.sample_names)
        if unknown:
            raise KeyError(
                f"no sample(s) {', '.join(sorted(map(repr, unknown)))}; samples: "
                f"{', '.join(self.sample_names)}"
            )
        if roles is not None:
            roles = set(roles)
            keep = {name for name in keep if self.sample(name).role in roles}
        for name in list(keep):
            substrate = self.sample(name).substrate
            if isinstance(substrate, str) and self.has_sample(substrate):
                keep.add(substrate)
        return MeasurementSet(
            self.wavelength_nm,
            [s for s in self.samples if s.name in keep],
            n=self.n,
            metadata=dict(self.metadata),
            source=self.source,
        )

    def resample(self, wavelength_nm):
        """The set linearly interpolated onto other wavelengths (within the measured range).

        Parameters
        ----------
        wavelength_nm : array_like
            New wavelengths [nm], inside ``[wavelength_nm[0], wavelength_nm[-1]]``.
        """
        new = np.asarray(wavelength_nm, dtype=float)
        if new.ndim != 1 or new.size == 0 or not np.isfinite(new).all():
            raise ValueError("wavelength_nm must be a non-empty 1-D array of finite wavelengths")
        lo, hi = self.wavelength_nm[0], self.wavelength_nm[-1]
        if new.min() < lo or new.max() > hi:
            raise ValueError(
                f"cannot resample outside the measured range {lo:g}–{hi:g} nm (no extrapolation)"
            )
        samples = [
            Sample(
                s.name,
                s.role,
                tuple(
                    Measurement(
                        m.kind,
                        m.label,
                        m.theta_i,
                        m.theta_o,
                        m.delta_phi,
                        m.specular,
                        np.interp(new, self.wavelength_nm, m.values),
                    )
                    for m in s.measurements
                ),
                s.substrate,
                s.film_group,
                s.opaque,
                s.thickness_um,
                s.concentration,
                s.eps,
            )
            for s in self.samples
        ]
        return MeasurementSet(
            new, samples, n=self.n, metadata=dict(self.metadata), source=self.source
        )

    # ---------------------------------------------------------------- output
    def to_csv(self, path):
        """Write the set as a bayespig CSV file (atomically); see ``docs/file-formats.md``."""
        write_csv(self, path)

    def to_astm_e1392(self, path, sample=None):
        """Write one sample's BRDFs as an ASTM E1392 text file (atomically)."""
        write_astm_e1392(self, path, sample=sample)

    def summary(self):
        """A human-readable description: samples, roles, substrates, wavelengths, methods."""
        return _summary(self)

    def __eq__(self, other):
        if not isinstance(other, MeasurementSet):
            return NotImplemented
        return (
            self.wavelength_nm.shape == other.wavelength_nm.shape
            and np.array_equal(self.wavelength_nm, other.wavelength_nm)
            and self.samples == other.samples
            and self.n == other.n
            and dict(self.metadata) == dict(other.metadata)
        )

    __hash__ = None

    def __repr__(self):
        names = list(self.sample_names[:REPR_SAMPLES])
        shown = f"{names}"[:-1] + (", ...]" if len(self.samples) > REPR_SAMPLES else "]")
        return (
            f"MeasurementSet({len(self.samples)} samples {shown}, "
            f"{self.n_wavelengths} wavelengths "
            f"{self.wavelength_nm[0]:g}–{self.wavelength_nm[-1]:g} nm)"
        )


# ---------------------------------------------------------------- validation
def set_problems(wavelength_nm, samples):
    """Problems of a set of samples as a whole (lengths, names, substrates, film groups).

    Returns
    -------
    list of Problem
        Each names the sample and field (and measurement index where it applies).
    """
    problems = []
    names = {}
    n_wl = len(wavelength_nm)
    if not samples:
        problems.append(Problem("a measurement set needs at least one sample", field="samples"))
    for sample in samples:
        if not isinstance(sample, Sample):
            problems.append(
                Problem(
                    f"samples must be Sample objects, got {type(sample).__name__}", field="samples"
                )
            )
            continue
        if sample.name in names:
            problems.append(
                Problem(
                    f"sample name {sample.name!r} is used twice", field="sample", sample=sample.name
                )
            )
        names[sample.name] = sample
        for index, m in enumerate(sample.measurements):
            if m.values.shape != (n_wl,):
                problems.append(
                    Problem(
                        f"{m.label} has {m.values.size} values but the set has {n_wl} wavelengths",
                        field="values",
                        sample=sample.name,
                        measurement=index,
                    )
                )
    valid = [s for s in samples if isinstance(s, Sample)]
    for sample in valid:
        substrate = sample.substrate
        if not isinstance(substrate, str):
            continue
        if substrate in names:
            if names[substrate].role not in SUBSTRATE_ROLES:
                problems.append(
                    Problem(
                        f"substrate {substrate!r} is a {names[substrate].role} sample; a film's "
                        "substrate must "
                        f"have role {' or '.join(SUBSTRATE_ROLES)}",
                        field="substrate",
                        sample=sample.name,
                    )
                )
            elif not names[substrate].reflectance_measurements:
                problems.append(
                    Problem(
                        f"substrate sample {substrate!r} has no reflectance measurement",
                        field="substrate",
                        sample=sample.name,
                    )
                )
        elif substrate not in _NAMED_SUBSTRATES:
            problems.append(
                Problem(
                    f"substrate sample {substrate!r} is missing: it is not a sample of this "
                    "set, nor 'black', "
                    f"'white' or an albedo in [0, 1]; add the bare substrate's measurement as a "
                    "sample named "
                    f"{substrate!r} with role 'substrate'",
                    field="substrate",
                    sample=sample.name,
                )
            )
    groups = {}
    for sample in valid:
        if sample.role in FILM_ROLES:
            groups.setdefault(sample.group, []).append(sample)
    for group, films in groups.items():
        if len({f.opaque for f in films}) > 1:
            problems.append(
                Problem(
                    f"film group {group!r} mixes opaque and non-opaque films "
                    f"({', '.join(f.name for f in films)}); "
                    "films of one group share tau",
                    field="opaque",
                    sample=films[-1].name,
                )
            )
        for attribute in ("thickness_um", "concentration"):
            values = {getattr(f, attribute) for f in films} - {None}
            if len(values) > 1:
                problems.append(
                    Problem(
                        f"film group {group!r} has different {attribute} "
                        f"({', '.join(map(str, sorted(values)))}); "
                        "films of one group share thickness and concentration",
                        field=attribute,
                        sample=films[-1].name,
                    )
                )
    return problems


def _albedo_from_air(substrate, n):
    estimates = []
    for m in substrate.reflectance_measurements:
        try:
            if m.kind == "hemispherical":
                r_s = substrate_albedo_from_air(
                    m.values, n=n, kind="hemispherical", theta_i=m.theta_i, specular=m.specular
                )
            else:
                brdf = m.values / np.pi if m.kind == "reflectance_factor" else m.values
                r_s = substrate_albedo_from_air(
                    brdf, n=n, kind="brdf", theta_i=m.theta_i, theta_o=m.theta_o
                )
        except ValueError as error:
            raise MeasurementError(
                Problem(
                    f"{m.label}: cannot be a Lambertian substrate under binder (eq. 9): {error}",
                    field="values",
                    sample=substrate.name,
                )
            ) from None
        estimates.append(r_s)
    return np.mean(estimates, axis=0)


def _mean_albedo(measurements, film):
    try:
        return float(np.mean(measurements.substrate_albedo(film)))
    except MeasurementError:
        return float("nan")


def _method_support(measurements, method):
    films = [s for s in measurements.samples if s.role in FILM_ROLES and s.reflectance_measurements]
    opaque = [f for f in films if f.opaque]
    albedo = {f.name: _mean_albedo(measurements, f) for f in films if not f.opaque}
    thin = [f for f in films if not f.opaque and math.isfinite(albedo[f.name])]
    glass = [
        s for s in measurements.samples if s.role == "film_on_glass" and s.transmittance is not None
    ]
    thin_text = "a non-opaque film on a substrate with reflectance measurements"
    opaque_text = "an opaque film with reflectance measurements"
    if method == "method1":
        missing = []
        if not opaque:
            missing.append(f"{opaque_text} (no sample with opaque = yes)")
        if not glass:
            missing.append(
                "a film on glass with a specular transmittance (no sample with role "
                "'film_on_glass' "
                "and measurement 'specular_transmittance')"
            )
        if missing:
            return MethodSupport(method, False, (), "method1 needs " + " and ".join(missing))
        return MethodSupport(
            method,
            True,
            (opaque[0].name, glass[0].name),
            f"opaque film {opaque[0].name!r} for a, film on glass {glass[0].name!r} for tau "
            "(eq. 6)",
        )
    if method == "method2":
        missing = []
        if not opaque:
            missing.append(f"{opaque_text} (no sample with opaque = yes)")
        if not thin:
            missing.append(f"{thin_text} (none found)")
        if missing:
            return MethodSupport(method, False, (), "method2 needs " + " and ".join(missing))
        thin_film = min(thin, key=lambda f: albedo[f.name])
        return MethodSupport(
            method,
            True,
            (opaque[0].name, thin_film.name),
            f"opaque film {opaque[0].name!r} for a, thin film {thin_film.name!r} for tau",
        )
    if method == "method3":
        if not thin:
            return MethodSupport(method, False, (), f"method3 needs {thin_text} (none found)")
        thin_film = min(thin, key=lambda f: albedo[f.name])
        return MethodSupport(
            method, True, (thin_film.name,), f"thin film {thin_film.name!r} for a and tau"
        )
    if method == "method4":
        best = None
        for group, members in _groups(thin).items():
            dark = min(members, key=lambda f: albedo[f.name])
            light = max(members, key=lambda f: albedo[f.name])
            if albedo[light.name] > albedo[dark.name]:
                best = best or (group, dark, light)
        if best is None:
            if not thin:
                found = "there is no non-opaque film on a substrate with reflectance measurements"
            else:
                found = "; ".join(
                    f"film group {g!r} has only {', '.join(repr(f.name) for f in m)}"
                    + ("" if len(m) == 1 else " on the same substrate albedo")
                    for g, m in _groups(thin).items()
                )
            return MethodSupport(
                method,
                False,
                (),
                "method4 needs the same film (one film_group) on a black and on a white substrate; "
                f"{found}: add the film over the other substrate with the same film_group",
            )
        group, dark, light = best
        return MethodSupport(
            method,
            True,
            (dark.name, light.name),
            f"film group {group!r}: {dark.name!r} on the darker and {light.name!r} on the "
            "lighter substrate",
        )
    raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")


def _groups(films):
    groups = {}
    for film in films:
        groups.setdefault(film.group, []).append(film)
    return groups


def _describe_substrate(measurements, sample):
    if sample.role in SUBSTRATE_ROLES:
        return "-"
    if sample.opaque:
        return "hidden (opaque)"
    if sample.substrate is None:
        return "-"
    if isinstance(sample.substrate, float):
        return f"r_s = {sample.substrate:g}"
    if isinstance(sample.substrate, str) and measurements.has_sample(sample.substrate):
        try:
            r_s = measurements.substrate_albedo(sample)
            return f"sample {sample.substrate!r} (r_s {r_s.min():.3g}–{r_s.max():.3g})"
        except MeasurementError as error:
            return f"sample {sample.substrate!r} (r_s not derivable: {error})"
    return f"{sample.substrate} (r_s = {_NAMED_SUBSTRATES[sample.substrate]:g})"


def _summary(measurements):
    wl = measurements.wavelength_nm
    steps = np.unique(np.round(np.diff(wl), 9))
    step = (
        f", step {steps[0]:g} nm"
        if steps.size == 1
        else (", irregular steps" if steps.size else "")
    )
    count = len(measurements.samples)
    lines = [
        (
            f"{count} sample{'s' if count != 1 else ''}; {wl.size} wavelengths "
            f"{wl[0]:g}–{wl[-1]:g} nm{step}; "
            f"binder n = {measurements.n:g}"
        )
    ]
    lines.append("samples:")
    width = max(len(s.name) for s in measurements.samples)
    for s in measurements.samples:
        kinds = {}
        for m in s.measurements:
            kinds.setdefault(m.kind, []).append(m.label)
        what = "; ".join(f"{k} at {', '.join(v)}" for k, v in kinds.items())
        extra = []
        if s.role in FILM_ROLES:
            extra.append(f"film group {s.group!r}")
        for attribute in ("thickness_um", "concentration", "eps"):
            if getattr(s, attribute) is not None:
                extra.append(f"{attribute} = {getattr(s, attribute):g}")
        lines.append(
            f"  {s.name:<{width}}  {s.role:<22}  substrate: {_describe_substrate(measurements, s)}"
            + (f"; {'; '.join(extra)}" if extra else "")
        )
        lines.append(f"  {'':<{width}}  {what}")
    lines.append("methods:")
    for method, support in measurements.supported_methods().items():
        lines.append(f"  {method}: {'yes' if support else 'no '} - {support.reason}")
    if measurements.metadata:
        lines.append("metadata:")
        for key, value in measurements.metadata.items():
            text = json.dumps(value)
            lines.append(f"  {key}: {text if len(text) <= 100 else text[:97] + '...'}")
    return "\n".join(lines)
