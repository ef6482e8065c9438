"""Colour of spectral reflectances: CIE XYZ, CIELAB and CIEDE2000 (via colour-science).

The conversions follow colour-science's names (``a_to_b``) and numbers. The central
object is a *weighting matrix* ``W`` of shape ``(n_wavelengths, 3)`` such that, for any
batch of reflectance spectra ``R`` of shape ``(..., n_wavelengths)``,

    ``XYZ = R @ W``

equals ``colour.sd_to_XYZ(sd, cmfs, illuminant, method=method) / 100`` for every
spectrum, where ``sd = colour.SpectralDistribution(R_i, wavelength_nm)``,
``cmfs = colour.MSDS_CMFS[observer]`` and ``illuminant = colour.SDS_ILLUMINANTS[illuminant]``
(the datasets as colour-science ships them; colour-science aligns the illuminant to the
observer's spectral shape, interpolates and extrapolates the reflectance onto its working
grid, and -- for ``"ASTM E308"`` -- applies the ASTM E2022/E308 weighting tables).
Every one of those steps is linear in the reflectance, so ``W`` is built exactly by
pushing the unit impulse spectra of the grid through ``sd_to_XYZ`` once per
(wavelengths, observer, illuminant, method) and cached. Converting 10^4 spectra then
costs one small matrix product instead of 10^4 calls.

Scale convention: XYZ here is on the 0-1 scale, with ``Y = 1`` for the perfect
reflecting diffuser (``R = 1`` at every wavelength); colour-science's ``sd_to_XYZ``
returns the same numbers times 100. CIELAB ``L*`` is 0-100 as usual. All calls into
colour-science run under its ``"reference"`` domain-range scale, so a user's global
``colour.set_domain_range_scale`` does not change these results.

Defaults: CIE 1964 10 degree standard observer and CIE illuminant D65
(:data:`DEFAULT_OBSERVER`, :data:`DEFAULT_ILLUMINANT`); both are selectable by the names
colour-science uses (:data:`OBSERVERS`, :data:`ILLUMINANTS`), and
:func:`colorimetric_metadata` states the conditions of a conversion for reports.

References
----------
ASTM E308-15, Standard Practice for Computing the Colors of Objects by Using the CIE
System. ASTM E2022-11, Standard Practice for Calculation of Weighting Factors for
Tristimulus Integration. CIE 15:2004, Colorimetry.
G. Sharma, W. Wu, E. N. Dalal (2005), The CIEDE2000 color-difference formula:
implementation notes, supplementary test data, and mathematical observations,
Color Research & Application 30(1), 21-30.
"""

from __future__ import annotations

import functools
import warnings

import colour
import numpy as np
from colour.colorimetry import MSDS_CMFS_STANDARD_OBSERVER
from colour.utilities import ColourRuntimeWarning, ColourUsageWarning

from ._validation import real_array

__all__ = [
    "DEFAULT_ILLUMINANT",
    "DEFAULT_OBSERVER",
    "ILLUMINANTS",
    "METHODS",
    "OBSERVERS",
    "XYZ_to_Lab",
    "colorimetric_metadata",
    "delta_E2000",
    "reflectance_to_Lab",
    "reflectance_to_XYZ",
    "weighting_matrix",
    "white_point_XYZ",
]

DEFAULT_OBSERVER = "CIE 1964 10 Degree Standard Observer"
"""Default standard observer (colour-science name)."""

DEFAULT_ILLUMINANT = "D65"
"""Default illuminant (colour-science name)."""

OBSERVERS = tuple(MSDS_CMFS_STANDARD_OBSERVER.keys())
"""Valid observer names (colour-science's standard observers, with its aliases)."""

ILLUMINANTS = tuple(colour.SDS_ILLUMINANTS.keys())
"""Valid illuminant names (colour-science's spectral illuminants)."""

METHODS = ("ASTM E308", "Integration")
"""Valid ``sd_to_XYZ`` methods; ``None`` chooses per grid (see :func:`weighting_matrix`)."""

NEGATIVE_REFLECTANCE_TOLERANCE = 1e-3
"""Reflectances down to ``-NEGATIVE_REFLECTANCE_TOLERANCE`` (noise on black samples) are
accepted and used as given; anything more negative is rejected."""

MIN_WAVELENGTHS = 6
"""colour-science's spectral interpolators need at least this many samples."""

_ASTM_INTERVALS_NM = (1.0, 5.0, 10.0, 20.0)
_REFERENCE_GRID_NM = np.arange(360.0, 781.0, 1.0)  # white point default: 1 nm, 360-780 nm
_VISIBLE_NM = (380.0, 780.0)


def _resolve_name(name, valid, argument):
    if not isinstance(name, str) or name not in valid:
        raise ValueError(
            f"{argument}={name!r} is not known to colour-science; valid names: " + ", ".join(valid)
        )


def _check_wavelengths(wavelength_nm):
    wl = real_array("wavelength_nm", wavelength_nm, allow_inf=True)  # inf: refused below
    if wl.ndim != 1 or wl.size < MIN_WAVELENGTHS:
        raise ValueError(
            f"wavelength_nm must be a 1-D array of at least {MIN_WAVELENGTHS} wavelengths "
            f"[nm], got shape {wl.shape}"
        )
    if not np.all(np.isfinite(wl)):
        raise ValueError("wavelength_nm contains NaN or infinite values")
    if np.any(np.diff(wl) <= 0):
        raise ValueError("wavelength_nm must be strictly increasing")
    if wl[0] >= _VISIBLE_NM[1] or wl[-1] <= _VISIBLE_NM[0]:
        raise ValueError(
            f"wavelength_nm spans {wl[0]:g}-{wl[-1]:g} nm and misses the visible range "
            f"{_VISIBLE_NM[0]:g}-{_VISIBLE_NM[1]:g} nm"
        )
    return wl


def _auto_method(wl):
    """``"ASTM E308"`` where colour-science's ASTM E308 path applies cleanly, else integration."""
    steps = np.diff(wl)
    interval = steps[0]
    regular = np.allclose(steps, interval, rtol=0.0, atol=1e-9)
    if not regular or not any(np.isclose(interval, i) for i in _ASTM_INTERVALS_NM):
        return "Integration"
    if interval >= 10.0 and (wl[0] % 10.0 != 0.0 or wl[-1] % 10.0 != 0.0):
        return "Integration"  # ASTM E308 leaves this case undefined
    return "ASTM E308"


@functools.lru_cache(maxsize=64)
def _weighting_matrix_cached(wavelengths, observer, illuminant, method):
    wl = np.array(wavelengths)
    cmfs = colour.MSDS_CMFS[observer]
    illuminant_sd = colour.SDS_ILLUMINANTS[illuminant]
    impulses = np.eye(wl.size)
    W = np.empty((wl.size, 3))
    with colour.domain_range_scale("reference"), warnings.catch_warnings():
        # colour-science reports every shape alignment it performs as a runtime warning;
        # the alignment is part of the documented contract here, not a surprise.
        warnings.simplefilter("ignore", ColourRuntimeWarning)
        warnings.simplefilter("ignore", ColourUsageWarning)
        for i, impulse in enumerate(impulses):
            sd = colour.SpectralDistribution(impulse, wl)
            W[i] = colour.sd_to_XYZ(sd, cmfs, illuminant_sd, method=method)
    W /= 100.0
    W.setflags(write=False)
    return W


def weighting_matrix(
    wavelength_nm, *, observer=DEFAULT_OBSERVER, illuminant=DEFAULT_ILLUMINANT, method=None
):
    """Tristimulus weighting matrix ``W`` with ``XYZ = R @ W`` (0-1 scale).

    Parameters
    ----------
    wavelength_nm : array_like, shape (n_wavelengths,)
        Strictly increasing wavelengths [nm] at which reflectances are sampled (any grid
        with at least :data:`MIN_WAVELENGTHS` points that overlaps 380-780 nm).
    observer : str
        Standard observer, a name from :data:`OBSERVERS`
        (default CIE 1964 10 degree).
    illuminant : str
        Illuminant, a name from :data:`ILLUMINANTS` (default D65).
    method : {None, "ASTM E308", "Integration"}
        ``colour.sd_to_XYZ`` method. ``None`` picks ``"ASTM E308"`` (colour-science's
        default, ASTM E308-15 weighting tables) for regular grids of 1, 5, 10 or 20 nm
        (10 and 20 nm grids starting and ending on a multiple of 10 nm) and
        ``"Integration"`` (interpolation to 1 nm, then summation) otherwise.

    Returns
    -------
    numpy.ndarray, shape (n_wavelengths, 3)
        Read-only weights [1 per unit reflectance]; ``R @ W`` equals
        ``colour.sd_to_XYZ(SpectralDistribution(R, wavelength_nm), MSDS_CMFS[observer],
        SDS_ILLUMINANTS[illuminant], method=method) / 100`` and ``W.sum(axis=0)`` is the
        white point with ``Y = 1``.
    """
    wl = _check_wavelengths(wavelength_nm)
    _resolve_name(observer, OBSERVERS, "observer")
    _resolve_name(illuminant, ILLUMINANTS, "illuminant")
    if method is None:
        method = _auto_method(wl)
    elif method not in METHODS:
        raise ValueError(
            f"method={method!r} is not valid; valid methods: None, " + ", ".join(METHODS)
        )
    elif method == "ASTM E308" and _auto_method(wl) != "ASTM E308":
        raise ValueError(
            "method='ASTM E308' needs a regular 1, 5, 10 or 20 nm grid (10/20 nm on multiples "
            "of 10 nm); use method='Integration' or method=None for this wavelength_nm"
        )
    observer = MSDS_CMFS_STANDARD_OBSERVER[observer].name
    return _weighting_matrix_cached(tuple(wl.tolist()), observer, illuminant, method)


def colorimetric_metadata(
    wavelength_nm, *, observer=DEFAULT_OBSERVER, illuminant=DEFAULT_ILLUMINANT, method=None
):
    """Conditions of a conversion, for reports and saved results.

    Parameters are those of :func:`weighting_matrix`.

    Returns
    -------
    dict
        ``observer``, ``illuminant``, ``method`` (the ``sd_to_XYZ`` method actually used),
        ``XYZ_scale``, ``white_point_XYZ`` (list of 3), ``wavelength_nm`` (first, last,
        count) and ``colour_science_version``.
    """
    wl = _check_wavelengths(wavelength_nm)
    W = weighting_matrix(wl, observer=observer, illuminant=illuminant, method=method)
    return {
        "observer": MSDS_CMFS_STANDARD_OBSERVER[observer].name,
        "illuminant": illuminant,
        "method": _auto_method(wl) if method is None else method,
        "XYZ_scale": "0-1, Y of the perfect reflecting diffuser = 1",
        "white_point_XYZ": W.sum(axis=0).tolist(),
        "wavelength_nm": {"first": float(wl[0]), "last": float(wl[-1]), "count": int(wl.size)},
        "colour_science_version": colour.__version__,
    }


def _check_reflectance(reflectance, n_wavelengths):
    R = real_array("reflectance", reflectance, allow_inf=True)  # inf: refused below
    if R.ndim == 0 or R.shape[-1] != n_wavelengths:
        raise ValueError(
            f"reflectance has shape {R.shape}; its last axis must match the "
            f"{n_wavelengths} values of wavelength_nm"
        )
    if np.isnan(R).any() or np.isinf(R).any():
        raise ValueError("reflectance contains NaN or infinite values")
    if R.size and R.min() < -NEGATIVE_REFLECTANCE_TOLERANCE:
        raise ValueError(
            f"reflectance has values down to {R.min():.4g}, below "
            f"-{NEGATIVE_REFLECTANCE_TOLERANCE:g}; reflectances are fractions (0-1)"
        )
    return R


def reflectance_to_XYZ(
    reflectance,
    wavelength_nm,
    *,
    observer=DEFAULT_OBSERVER,
    illuminant=DEFAULT_ILLUMINANT,
    method=None,
):
    """CIE XYZ tristimulus values of reflectance spectra.

    Parameters
    ----------
    reflectance : array_like, shape (..., n_wavelengths)
        Spectral reflectance factors [1] (fractions, not percent) on ``wavelength_nm``.
    wavelength_nm : array_like, shape (n_wavelengths,)
        Wavelengths [nm], strictly increasing.
    observer, illuminant, method
        See :func:`weighting_matrix`; defaults CIE 1964 10 degree observer, D65, and the
        ASTM E308 method where the grid allows it.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        XYZ [1] on the 0-1 scale (``Y = 1`` for ``reflectance = 1``); equal to
        ``colour.sd_to_XYZ(...) / 100`` for each spectrum.
    """
    W = weighting_matrix(wavelength_nm, observer=observer, illuminant=illuminant, method=method)
    R = _check_reflectance(reflectance, W.shape[0])
    return R @ W


def white_point_XYZ(
    wavelength_nm=None, *, observer=DEFAULT_OBSERVER, illuminant=DEFAULT_ILLUMINANT, method=None
):
    """XYZ of the perfect reflecting diffuser (``Y = 1``).

    Parameters
    ----------
    wavelength_nm : array_like or None
        Grid whose weights define the white (ASTM E308 practice: the white is computed
        with the same weights as the samples). ``None`` uses 360-780 nm at 1 nm.
    observer, illuminant, method
        See :func:`weighting_matrix`.

    Returns
    -------
    numpy.ndarray, shape (3,)
        White point XYZ [1], ``Y = 1``.
    """
    grid = _REFERENCE_GRID_NM if wavelength_nm is None else wavelength_nm
    W = weighting_matrix(grid, observer=observer, illuminant=illuminant, method=method)
    return W.sum(axis=0)


def _check_triplets(values, argument):
    v = real_array(argument, values, allow_inf=True)  # inf: refused below
    if v.ndim == 0 or v.shape[-1] != 3:
        raise ValueError(f"{argument} must have a last axis of length 3, got shape {v.shape}")
    if np.isnan(v).any() or np.isinf(v).any():
        raise ValueError(f"{argument} contains NaN or infinite values")
    return v


def XYZ_to_Lab(XYZ, *, white_XYZ=None, observer=DEFAULT_OBSERVER, illuminant=DEFAULT_ILLUMINANT):
    """CIELAB of XYZ tristimulus values (``colour.XYZ_to_Lab``).

    Parameters
    ----------
    XYZ : array_like, shape (..., 3)
        Tristimulus values [1] on the 0-1 scale.
    white_XYZ : array_like, shape (3,), optional
        Reference white XYZ [1]. Default: :func:`white_point_XYZ` of ``observer`` and
        ``illuminant`` (360-780 nm at 1 nm), i.e. the white matching the observer.
    observer, illuminant : str
        Used only when ``white_XYZ`` is not given (defaults CIE 1964 10 degree, D65).

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        ``L*`` [0-100], ``a*``, ``b*``.
    """
    XYZ = _check_triplets(XYZ, "XYZ")
    if white_XYZ is None:
        white = white_point_XYZ(observer=observer, illuminant=illuminant)
    else:
        white = _check_triplets(white_XYZ, "white_XYZ")
        if white.shape != (3,) or np.any(white <= 0):
            raise ValueError("white_XYZ must be three positive values (X, Y, Z)")
    # colour takes the white as xy or xyY; xyY keeps the white's own Y.
    white_xyY = np.array([white[0] / white.sum(), white[1] / white.sum(), white[1]])
    with colour.domain_range_scale("reference"):
        return colour.XYZ_to_Lab(XYZ, illuminant=white_xyY)


def reflectance_to_Lab(
    reflectance,
    wavelength_nm,
    *,
    observer=DEFAULT_OBSERVER,
    illuminant=DEFAULT_ILLUMINANT,
    method=None,
):
    """CIELAB of reflectance spectra.

    The reference white is computed with the same weights as the samples (ASTM E308), so
    ``reflectance = 1`` gives exactly ``L* = 100, a* = b* = 0``.

    Parameters
    ----------
    reflectance, wavelength_nm, observer, illuminant, method
        See :func:`reflectance_to_XYZ`.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        ``L*`` [0-100], ``a*``, ``b*``.
    """
    XYZ = reflectance_to_XYZ(
        reflectance, wavelength_nm, observer=observer, illuminant=illuminant, method=method
    )
    white = white_point_XYZ(wavelength_nm, observer=observer, illuminant=illuminant, method=method)
    return XYZ_to_Lab(XYZ, white_XYZ=white)


def delta_E2000(Lab_1, Lab_2):
    """CIEDE2000 colour difference (``colour.delta_E(..., method="CIE 2000")``).

    Parameters
    ----------
    Lab_1, Lab_2 : array_like, shape (..., 3)
        CIELAB values (``L*`` 0-100); broadcast against each other.

    Returns
    -------
    numpy.ndarray, shape (...)
        Delta E 2000 [CIELAB units], with ``k_L = k_C = k_H = 1``.

    References
    ----------
    Sharma, Wu & Dalal (2005), Color Res. Appl. 30(1), 21-30.
    """
    a = _check_triplets(Lab_1, "Lab_1")
    b = _check_triplets(Lab_2, "Lab_2")
    try:
        a, b = np.broadcast_arrays(a, b)
    except ValueError as error:
        raise ValueError(
            f"Lab_1 with shape {a.shape} and Lab_2 with shape {b.shape} do not broadcast"
        ) from error
    with colour.domain_range_scale("reference"):
        return np.asarray(colour.delta_E(a, b, method="CIE 2000"), dtype=float)
