"""The surface roughness as a parameter shared over wavelengths (issue 16).

A paint's top surface has one roughness ``alpha`` (GGX's alpha of the air/binder interface,
:mod:`bayespig.physics.rough_surface`) at every wavelength: it couples the wavelengths, so it is
a spec (:class:`RoughnessSpec`) of the joint machinery for shared parameters
(:mod:`bayespig.inference.shared`), entering the forward model through the per-row input
``roughness`` of :class:`bayespig.likelihood.WavelengthModel` (which interpolates the rough
tables, :mod:`bayespig.rough_table`, along their roughness axis).

Prior
-----
One coordinate ``log alpha`` per measurement set (one surface per paint: every film of the set
is the same paint), **log-uniform** on the rough tables' roughness range
(:data:`bayespig.rough_table.ROUGHNESS_MIN` .. :data:`~bayespig.rough_table.ROUGHNESS_MAX`,
0.01 .. 1 by default): the roughness is a scale parameter, from a fine gloss (a lobe ~1 deg wide)
to a matt surface, and nothing favours one decade over another. It is stored as the posterior
variable ``roughness`` over ``(chain, draw, surface)``; its prior bounds are recorded with the
others (``prior_bounds``, scale ``log``), so the prior-edge flags cover it.

Binder index
------------
The binder index ``n`` sets the surface's Fresnel reflection (the lobe's height) and what the
facets do to the light entering and leaving the layer; on real gonio paints it is not known to
better than a few hundredths, and the lobe's height is what tells it (the Cornell paints:
``reports/cornell.md``). :class:`BinderIndexSpec` makes it a shared parameter of the same joint
run: one coordinate ``n`` per set, prior ``N(1.45, 0.05^2)`` (issue 16; user-settable) truncated
to the binder-index tables' range (:data:`bayespig.rough_table.BINDER_INDEX_NODES`, 1.37 .. 1.77),
entering the forward model as the per-row input ``binder_index``
(:class:`bayespig.rough_table.BinderIndexRoughTables`). It is stored as ``binder_index`` over
``(chain, draw, surface)``, its bounds in ``prior_bounds`` (the truncation is the prior edge the
flags watch).

Noise floor in the joint run
----------------------------
Real gonio data (exact zeros, dark directions) need the additive noise floor of
:mod:`bayespig.likelihood`. :class:`NoiseFloorFilmLayout` is the film layout
(:class:`bayespig.inference.shared.FilmLayout`) with one more coordinate per wavelength,
``log sigma0`` (log-uniform on ``priors.noise_floor_range``, as in the per-wavelength runs), and
the likelihood ``N(x_obs | x, (eps x)^2 + sigma0^2)`` (the layout's ``log_density``).
:func:`bayespig.inference.shared.sample_joint` runs it as it runs the plain film layout, and its
records then carry the floor's draws.
"""

from __future__ import annotations

import numpy as np

from ..likelihood import censored_zero_logpdf
from .shared import FilmLayout, SharedParameter

_LOG_2PI = float(np.log(2.0 * np.pi))

__all__ = [
    "BINDER_INDEX_PRIOR",
    "FLAKE_ROUGHNESS_RANGE",
    "ROUGHNESS_START_SD",
    "BinderIndexSpec",
    "FlakeRoughnessSpec",
    "NoiseFloorFilmLayout",
    "RoughnessSpec",
    "binder_index_argument",
    "binder_index_prior_argument",
    "incidence_offset_scale",
    "roughness_argument",
]

#: Draws per chain kept by the pilot of a roughness or noise-floor joint run: it only gives the
#: blocks' medians and start points, and its stored per-draw predictions would be most of the memory.
PILOT_DRAWS_PER_CHAIN = 128
#: Spread of the walkers' start around the nominal ``log alpha`` [-].
ROUGHNESS_START_SD = 0.02
#: Default prior of the binder index: normal (mean, sd) [-], truncated to the tables' range (issue 16).
BINDER_INDEX_PRIOR = (1.45, 0.05)
#: Spread of the walkers' start around the nominal binder index [-].
BINDER_INDEX_START_SD = 0.005
#: Prior support of the flakes' roughness [-]: from flakes aligned to within ~1 deg to flakes of
#: every orientation.
FLAKE_ROUGHNESS_RANGE = (0.02, 1.0)
#: Flake roughness of the start [-] (the Cornell garnet red's least-squares value is ~0.35:
#: ``python benchmarks/cornell_surface_models.py``).
FLAKE_ROUGHNESS_NOMINAL = 0.3
#: Spread of the walkers' start around the nominal ``log alpha_f`` [-].
FLAKE_ROUGHNESS_START_SD = 0.05


def roughness_argument(roughness, name="roughness"):
    """``roughness`` checked: ``"free"``, None (the default for the set), or a number >= 0.

    Returns
    -------
    None, "free" or float

    Raises
    ------
    TypeError, ValueError
        Naming ``name``, for anything else.
    """
    expected = ("'free' (inferred), or a number >= 0 (the GGX alpha of the top surface, fixed; "
                "0 for a smooth surface)")
    if roughness is None:
        return None
    if isinstance(roughness, str):
        if roughness.strip() != "free":
            raise ValueError(f"{name} must be {expected}, got {roughness!r}")
        return "free"
    if isinstance(roughness, (bool, np.bool_)) or not isinstance(roughness, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be {expected}, got {type(roughness).__name__} {roughness!r}")
    value = float(roughness)
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be {expected}, got {roughness!r}")
    return value


def binder_index_argument(binder_index, name="binder_index"):
    """``binder_index`` checked: None (the set's own ``n``, fixed) or ``"free"`` (inferred).

    Raises
    ------
    TypeError, ValueError
        Naming ``name``, for anything else (a fixed index other than the set's is the set's ``n``:
        ``read_measurements(..., n=...)``).
    """
    if binder_index is None:
        return None
    if isinstance(binder_index, str) and binder_index.strip() == "free":
        return "free"
    raise ValueError(f"{name} must be None (the measurement set's binder index, fixed) or 'free' (inferred "
                     f"jointly with the roughness; prior N({BINDER_INDEX_PRIOR[0]}, {BINDER_INDEX_PRIOR[1]}^2)), "
                     f"got {binder_index!r}")


def binder_index_prior_argument(prior, name="binder_index_prior"):
    """``prior`` checked: None (:data:`BINDER_INDEX_PRIOR`) or ``(mean, sd)`` with ``sd > 0`` [-].

    Returns
    -------
    (float, float)

    Raises
    ------
    TypeError, ValueError
        Naming ``name``.
    """
    if prior is None:
        return BINDER_INDEX_PRIOR
    try:
        mean, sd = (float(v) for v in prior)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be (mean, sd) of the binder index's normal prior, got {prior!r}") from None
    if not (np.isfinite(mean) and mean > 1.0 and np.isfinite(sd) and sd > 0):
        raise ValueError(f"{name} must be (mean, sd) with mean > 1 and sd > 0, got {prior!r}")
    return mean, sd


class BinderIndexSpec(SharedParameter):
    """One binder index ``n`` for every film of a set: a spec of :mod:`bayespig.inference.shared`.

    Parameters
    ----------
    n_range : (float, float)
        Truncation of the prior [-] (the binder-index tables' range).
    nominal : float
        Index of the pilot run [-] (the set's ``n``), inside ``n_range``.
    prior : (float, float)
        Mean and sd of the normal prior [-] (default :data:`BINDER_INDEX_PRIOR`).
    label : str
        Name of the surface (the coordinate of the dimension ``surface``).
    """

    title = "binder index"
    variable = "binder_index"
    dimension = "surface"
    long_name = "refractive index of the binder at the films' top surface"
    units = "1"
    coordinate_name = "binder_index"
    attribute = "binder_index_prior"
    prior_scale = "linear"

    def __init__(self, n_range, nominal, prior=BINDER_INDEX_PRIOR, label="surface"):
        low, high = (float(v) for v in n_range)
        if not (1.0 < low < high and np.isfinite(high)):
            raise ValueError(f"n_range must be (low, high) with 1 < low < high, got {n_range!r}")
        if not low <= float(nominal) <= high:
            raise ValueError(f"nominal binder index {nominal!r} must lie in n_range {n_range!r}")
        mean, sd = binder_index_prior_argument(prior, "prior")
        self.n_range, self.prior = (low, high), (mean, sd)
        self.labels = (str(label),)
        self.lower, self.upper = np.array([low]), np.array([high])
        self.nominal = np.array([float(nominal)])
        self.start_sd = np.array([BINDER_INDEX_START_SD])

    def log_prior(self, x):
        """Normal in ``n`` (unnormalised; the truncation is the box), (W,)."""
        z = (np.asarray(x)[:, 0] - self.prior[0]) / self.prior[1]
        return -0.5 * z * z

    def physical(self, x):
        """``n`` itself."""
        return np.asarray(x, dtype=float)

    def model_inputs(self, x):
        """``binder_index``: every row's ``n``, (W,)."""
        return {"binder_index": np.asarray(x, dtype=float)[:, 0]}

    def describe_prior(self):
        """The prior as text (provenance)."""
        return (f"normal, mean {self.prior[0]:g}, sd {self.prior[1]:g}, truncated to [{self.n_range[0]:g}, "
                f"{self.n_range[1]:g}] (the binder-index tables' range), one n for every film of the set")

    def describe(self):
        """Range, prior, label (the ``binder_index_prior`` attribute)."""
        return {"n_range": list(self.n_range), "mean": self.prior[0], "sd": self.prior[1],
                "surfaces": list(self.labels), "nominal": float(self.nominal[0]), "prior": self.describe_prior()}


class RoughnessSpec(SharedParameter):
    """One roughness ``alpha`` for every film of a set: a spec of :mod:`bayespig.inference.shared`.

    Parameters
    ----------
    alpha_range : (float, float)
        Support of the log-uniform prior [-] (the rough tables' range).
    nominal : float
        Roughness of the pilot run [-] (the forward model's own), inside ``alpha_range``.
    label : str
        Name of the surface (the coordinate of the dimension ``surface``).
    """

    title = "surface roughness"
    variable = "roughness"
    dimension = "surface"
    long_name = "GGX roughness alpha of the films' top surface"
    units = "1"
    coordinate_name = "log_roughness"
    attribute = "roughness_prior"
    prior_scale = "log"

    def __init__(self, alpha_range, nominal, label="surface"):
        low, high = (float(v) for v in alpha_range)
        if not (0.0 < low < high and np.isfinite(high)):
            raise ValueError(f"alpha_range must be (low, high) with 0 < low < high, got {alpha_range!r}")
        if not low <= float(nominal) <= high:
            raise ValueError(f"nominal roughness {nominal!r} must lie in alpha_range {alpha_range!r}")
        self.alpha_range = (low, high)
        self.labels = (str(label),)
        self.lower = np.array([np.log(low)])
        self.upper = np.array([np.log(high)])
        self.nominal = np.array([np.log(float(nominal))])
        self.start_sd = np.array([ROUGHNESS_START_SD])

    def log_prior(self, x):
        """Log-uniform in ``alpha``: flat in the sampled ``log alpha`` (0 inside the box), (W,)."""
        return np.zeros(np.shape(x)[0])

    def physical(self, x):
        """``alpha = exp(log alpha)``."""
        return np.exp(x)

    def model_inputs(self, x):
        """``roughness``: every row's ``alpha``, (W,)."""
        return {"roughness": np.exp(np.asarray(x)[:, 0])}

    def describe_prior(self):
        """The prior as text (provenance)."""
        return (f"log-uniform on [{self.alpha_range[0]:g}, {self.alpha_range[1]:g}] "
                "(the rough look-up tables' range), one alpha for every film of the set")

    def describe(self):
        """Range, label and prior (the ``roughness_prior`` attribute)."""
        return {"alpha_range": list(self.alpha_range), "surfaces": list(self.labels),
                "nominal": float(np.exp(self.nominal[0])), "prior": self.describe_prior()}


class FlakeRoughnessSpec(SharedParameter):
    """One roughness of the effect-pigment flakes for every film of a set: a spec of
    :mod:`bayespig.inference.shared`.

    The flakes' lobe (:func:`bayespig.physics.forward.flake_brdf`) has a reflectance ``c`` per
    band (a block coordinate of the film layout, :class:`~bayespig.inference.shared.FilmLayout`)
    and one shape at every band: the spread of the flakes' orientations, GGX's ``alpha`` of their
    normals about the layer's normal. One coordinate ``log alpha_f``, log-uniform on
    ``alpha_range`` (:data:`FLAKE_ROUGHNESS_RANGE`), entering the forward model as the per-row
    input ``flake_roughness``; stored as ``flake_roughness`` over ``(chain, draw, surface)``.

    Parameters
    ----------
    alpha_range : (float, float)
        Support of the log-uniform prior [-].
    nominal : float
        Flake roughness of the start [-], inside ``alpha_range``.
    label : str
        Name of the surface (the coordinate of the dimension ``surface``).
    """

    title = "flake roughness"
    variable = "flake_roughness"
    dimension = "surface"
    long_name = "GGX roughness alpha of the effect-pigment flakes' orientations"
    units = "1"
    coordinate_name = "log_flake_roughness"
    attribute = "flake_roughness_prior"
    prior_scale = "log"

    def __init__(self, alpha_range=None, nominal=None, label="surface"):
        low, high = (float(v) for v in (alpha_range or FLAKE_ROUGHNESS_RANGE))
        nominal = FLAKE_ROUGHNESS_NOMINAL if nominal is None else float(nominal)
        if not (0.0 < low < high and np.isfinite(high)):
            raise ValueError(f"alpha_range must be (low, high) with 0 < low < high, got {alpha_range!r}")
        if not low <= nominal <= high:
            raise ValueError(f"nominal flake roughness {nominal!r} must lie in alpha_range {(low, high)!r}")
        self.alpha_range = (low, high)
        self.labels = (str(label),)
        self.lower, self.upper = np.array([np.log(low)]), np.array([np.log(high)])
        self.nominal = np.array([np.log(nominal)])
        self.start_sd = np.array([FLAKE_ROUGHNESS_START_SD])

    def log_prior(self, x):
        """Log-uniform in ``alpha_f``: flat in the sampled ``log alpha_f`` (0 inside the box), (W,)."""
        return np.zeros(np.shape(x)[0])

    def physical(self, x):
        """``alpha_f = exp(log alpha_f)``."""
        return np.exp(x)

    def model_inputs(self, x):
        """``flake_roughness``: every row's ``alpha_f``, (W,)."""
        return {"flake_roughness": np.exp(np.asarray(x)[:, 0])}

    def describe_prior(self):
        """The prior as text (provenance)."""
        return (f"log-uniform on [{self.alpha_range[0]:g}, {self.alpha_range[1]:g}], one flake roughness for "
                "every film of the set")

    def describe(self):
        """Range, label and prior (the ``flake_roughness_prior`` attribute)."""
        return {"alpha_range": list(self.alpha_range), "surfaces": list(self.labels),
                "nominal": float(np.exp(self.nominal[0])), "prior": self.describe_prior()}


class NoiseFloorFilmLayout(FilmLayout):
    """The film layout with an inferred additive noise floor per wavelength (and optionally the
    instrument's incidence offset).

    Blocks ``[a, log tau_1..G, (log c), log sigma0, (log b)]``; flat order ``[a (n_wl), log tau
    (n_wl * G), (log c (n_wl)), log sigma0 (n_wl), (log b (n_wl))]`` (``log c``: the flakes'
    reflectance of a model with flakes, :class:`~bayespig.inference.shared.FilmLayout`; ``log b``:
    the incidence offset, below); likelihood ``N(x_obs | m, (eps m)^2 + sigma0^2)`` with ``m`` the
    predicted reading.

    Incidence offset
    ----------------
    A gonioreflectometer measures a radiance and divides it by the irradiance ``E cos theta_i``
    on the sample. A constant error of its background (dark-signal or stray-light) subtraction,
    in radiance units, is then an additive error ``b / cos theta_i`` of the BRDF: 5.8 times
    larger at 80 deg incidence than at normal incidence, largest in relative terms where the
    paint is dark, and a background subtracted in excess shows as readings clipped to exactly 0
    at grazing incidence. With ``incidence_offset=True`` the predicted reading of a BRDF value is
    ``m = max(f - b / cos theta_i, 0)`` (``f`` the film's BRDF, ``b >= 0`` per band, log-uniform on
    ``priors.noise_floor_range``, in the units of the values; values of other channels are not
    offset). On the Cornell paints 1172 of the Krylon blue's 1218 exact zeros are at theta_i =
    80 deg, and the offset takes the least-squares residual at 420 nm from 33 % to 5 %
    (``python benchmarks/cornell_incidence_offset.py``).

    Parameters
    ----------
    model : ForwardModel
    priors : Priors
        ``noise_floor_range`` is the floor's (and the offset's) log-uniform support.
    eps : float
        Known relative error for films without their own [-].
    incidence_offset : bool
        Infer the incidence offset ``b`` per band.
    censored_zeros : bool
        The observed zeros are readings censored at 0 (:mod:`bayespig.likelihood`, "Censored
        zeros"): the reading is ``max(x, 0)`` of ``x ~ N(mu, (eps f)^2 + sigma0^2)``, ``mu = f - b /
        cos theta_i`` (``f`` without an offset), so a 0 has the likelihood ``Phi(-mu / sigma)`` and a
        positive reading the density ``N(x_obs | mu, sigma^2)``; the multiplicative error scales the
        paint's BRDF ``f``, not the offset. :meth:`predict` then gives ``mu`` (any sign) and
        :meth:`reading` the predicted reading ``max(mu, 0)`` (the reading's median).
    """

    def __init__(self, model, priors, eps, incidence_offset=False, censored_zeros=False):
        super().__init__(model, priors, eps)
        self.incidence_offset = bool(incidence_offset)
        self.censored_zeros = bool(censored_zeros)
        extra = ("log_noise_floor",) + (("log_incidence_offset",) if self.incidence_offset else ())
        self.names = self.names + extra
        n_wl = self.n_wavelengths
        low, high = (np.log(float(v)) for v in priors.noise_floor_range)
        self.lower = np.concatenate([self.lower, np.full((n_wl, len(extra)), low)], axis=1)
        self.upper = np.concatenate([self.upper, np.full((n_wl, len(extra)), high)], axis=1)
        self.offset_scale = incidence_offset_scale(model.problem)

    @property
    def flat_index(self):
        """``[a (n_wl), log tau (n_wl * G), (log c (n_wl)), log sigma0 (n_wl), (log b (n_wl))]``."""
        film = super().flat_index
        n_wl = self.n_wavelengths
        extra = [(n_wl * (self.film_size + j) + np.arange(n_wl))[:, None] for j in range(1 + self.incidence_offset)]
        return np.concatenate([film] + extra, axis=1)

    @property
    def parameter_names(self):
        """Those of the film layout, then ``r_log_noise_floor[w]`` (then ``r_log_incidence_offset[w]``)."""
        wl = [f"{w:g}" for w in self.wavelength_nm]
        names = super().parameter_names + tuple(f"r_log_noise_floor[{w}]" for w in wl)
        if self.incidence_offset:
            names += tuple(f"r_log_incidence_offset[{w}]" for w in wl)
        return names

    def predict(self, theta, inputs):
        """The predicted readings ``m`` from the blocks, (W, n_wl, n_values): the film's values,
        less the incidence offset when it is inferred, clipped at 0 (with ``censored_zeros`` not
        clipped: the mean ``mu`` of the reading before the instrument clips it)."""
        values = super().predict(theta[..., :self.film_size], inputs)
        offset = self.incidence_offset_of(theta)
        if offset is None:
            return values
        values -= offset[..., None] * self.offset_scale
        if not self.censored_zeros:
            np.maximum(values, 0.0, out=values)
        return values

    def reading(self, values):
        """The predicted readings from :meth:`predict`'s values: ``max(mu, 0)`` with
        ``censored_zeros`` (already clipped without)."""
        return np.maximum(values, 0.0) if self.censored_zeros else values

    def unpack(self, theta):
        """``a`` (W, n_wl) and ``tau`` (W, n_wl, G) (the floor: :meth:`noise_floor_of`)."""
        return super().unpack(theta[..., :self.film_size])

    def flake_reflectance_of(self, theta):
        """The flakes' reflectance ``c`` of every block (W, n_wl) [-] (None without flakes)."""
        return super().flake_reflectance_of(theta[..., :self.film_size])

    def noise_floor_of(self, theta):
        """The floor ``sigma0`` of every block (W, n_wl) [units of the values]."""
        return np.exp(theta[..., self.film_size])

    def incidence_offset_of(self, theta):
        """The incidence offset ``b`` of every block (W, n_wl) [units of the values] (None when
        it is not inferred)."""
        return np.exp(theta[..., self.film_size + 1]) if self.incidence_offset else None

    def log_density(self, theta, values):
        """Pointwise ``log N(x_obs | m, (eps m)^2 + sigma0^2)``, (W, n_wl, n_values), ``values`` the
        predicted readings ``m``.

        :func:`bayespig.likelihood.multiplicative_normal_logpdf` written on the variance (no
        ``hypot``, in place: this is half the joint run's time on 1439 geometries); the same
        density to round-off.
        """
        if self.censored_zeros:
            return self._censored_log_density(theta, values)
        floor = self.noise_floor_of(theta)[..., None]
        variance = np.multiply(values, self.eps)
        np.multiply(variance, variance, out=variance)
        variance += floor * floor
        residual = self.observed - values
        np.multiply(residual, residual, out=residual)
        residual /= variance
        np.log(variance, out=variance)
        residual += variance
        residual += _LOG_2PI
        residual *= -0.5
        return residual

    def _censored_log_density(self, theta, mean):
        """:meth:`log_density` with the observed zeros censored at 0: ``log Phi(-mu / sigma)`` for
        them, ``log N(x_obs | mu, sigma^2)`` for the rest, ``sigma^2 = (eps f)^2 + sigma0^2``."""
        floor = self.noise_floor_of(theta)[..., None]
        offset = self.incidence_offset_of(theta)
        paint = mean if offset is None else mean + offset[..., None] * self.offset_scale  # f
        variance = np.square(paint * self.eps) + floor * floor
        value = -0.5 * (np.square(self.observed - mean) / variance + np.log(variance) + _LOG_2PI)
        zero = self.observed == 0  # (n_wl, n_values)
        if zero.any():
            value[..., zero] = censored_zero_logpdf(mean[..., zero], variance[..., zero])
        return value


def incidence_offset_scale(problem):
    """Per value of a problem, how the incidence offset enters it: ``1 / cos theta_i`` for a BRDF
    channel, 0 for every other value (hemispherical, 45/0 and transmittance values are not
    offset), shape (n_values,) [-] (:class:`NoiseFloorFilmLayout`)."""
    parts = []
    for film in problem.films:
        if film.kind == "transmittance" or film.instrument is None:
            parts.append(np.zeros(film.observed.shape[1]))
            continue
        parts.append(np.array([1.0 / np.cos(np.radians(ch.theta_i)) if ch.kind == "brdf" else 0.0
                               for ch in film.instrument.channels]))
    return np.concatenate(parts)
