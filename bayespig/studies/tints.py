"""Tint prediction, the colour-matching step: a pigment's ~50/50 tint from masstone, white and 10/90 tint.

Protocol (identical for bayespig's radiative-transfer model and for two-constant
Kubelka-Munk with Saunderson correction; only the per-film calibration and the forward
model differ). Every film is measured over a dark and a light card (the paper's method 4).

1. **Calibrate each film** per wavelength from its two spectra: an *intensive* property
   ``u`` that does not depend on thickness, and an *extensive* one ``E`` (thickness times
   a coefficient):

   * bayespig: ``u = a`` (relative absorption), ``E = tau`` (optical thickness), from the
     method-4 point fit (:func:`bayespig.fit.fit_measurements`, paper section 3.3);
   * Kubelka-Munk: ``u = K/S``, ``E = S*X`` (:func:`bayespig.kubelka_munk.calibrate_film`).

2. **Pigment and white.** The masstone A gives the pigment's ``u_P``; the white film W
   (zinc white, Revigo 07A) gives ``u_W`` and its weight per unit concentration
   ``w_W = E_W / D_W^W``, in units of W's (unknown) thickness.

3. **Relative strength from the 10/90 tint B.** Both models mix the same way (paper
   section 2; Duncan's rule for Kubelka-Munk):
   ``u_mix = sum_i D_i w_i u_i / sum_i D_i w_i`` and ``E_mix = H sum_i D_i w_i`` with
   ``w = sigma_ext`` (bayespig) or ``w = S`` (Kubelka-Munk). B's intensive value then fixes
   the weight ratio per wavelength,
   ``y = D_P^B w_P / (D_W^B w_W) = (u_B - u_W) / (u_P - u_B)``.
   Where ``u_P`` and ``u_W`` are too close for the ratio to be determined, or ``u_B`` lies
   outside ``[u_W, u_P]`` (noise, or model error), ``log y`` is interpolated over
   wavelength from the determined bands (flagged in the result).

4. **Predict the tint C** over both cards: ``u_C`` by the mixing rule with C's
   concentrations, ``E_C = h (D_P^C w_P + D_W^C w_W)``. C's film thickness ``h`` (relative
   to W's) is unknown: it is the **one free scalar**, fitted to C's two spectra by least
   squares in relative deviation over all wavelengths (the same objective as the point fits
   of :mod:`bayespig.fit`). Everything else about C is predicted.

5. **Score**: CIEDE2000 between predicted and measured C over each card (D65, CIE 1964 10°,
   :mod:`bayespig.colorimetry`).

Concentrations ``D`` come from the mass fractions by appendix A2
(:func:`bayespig.physics.mixtures.concentrations_from_mass_fractions`; with unknown paste
densities they are proportional to the mass fractions). The per-pigment scale of ``D`` is
absorbed by ``w``, so only ratios between films matter.

References
----------
Ershov, Voloboy & Pozdnyakov (2023), section 2 (mixture rules), 3.3 (method 4), appendix A2.
D. R. Duncan (1940), Proc. Phys. Soc. 52, 390 (two-constant mixing).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from .. import colorimetry
from .. import kubelka_munk as km

__all__ = [
    "TINT_MODELS",
    "FilmCalibration",
    "KubelkaMunkTintModel",
    "ModelErrorRegion",
    "RadiativeTransferTintModel",
    "TintPosterior",
    "TintPrediction",
    "black_white_pair",
    "credible_region_contains",
    "cross_validated_model_error",
    "mixture_weight_ratio",
    "predict_tint",
    "tint_posterior_predictive",
]

TINT_MODELS = ("bayespig", "kubelka-munk")
#: Relative closeness of ``u_P`` and ``u_W`` below which B cannot fix the weight ratio.
DEGENERATE_RTOL = 0.05
#: Absolute floor of that closeness (a, K/S of ~1e-4 are below what 1 % spectra resolve).
DEGENERATE_ATOL = 1e-4
#: Relative rms of a method-4 fit above which other starts are tried (two values, two
#: parameters: a representable film is fitted exactly, so anything above ~0.2 % is a bound).
REFIT_RMS = 2e-3
#: Bounds of C's thickness factor relative to the white film's [1].
THICKNESS_BOUNDS = (1e-2, 1e2)


@dataclass(frozen=True)
class FilmCalibration:
    """A film's per-wavelength calibration: intensive ``u`` and extensive ``E`` (see the module)."""

    intensive: np.ndarray
    extensive: np.ndarray
    rms_relative_deviation: np.ndarray = field(default=None)


def black_white_pair(measurements):
    """The two films of a black/white measurement set, dark card first.

    Parameters
    ----------
    measurements : MeasurementSet
        One film group measured over two substrates (paper method 4), one hemispherical
        or other reflectance channel per film.

    Returns
    -------
    tuple
        ``(observed, r_s, channel)``: observed shape (2, n_wavelengths) [1] (first channel
        of each film), card albedo seen from the binder ``r_s`` shape (2, n_wavelengths)
        [1], and the first film's :class:`~bayespig.instruments.Channel`.

    Raises
    ------
    ValueError
        When the set does not hold exactly two reflectance films on measured or given cards.
    """
    films = [f for f in measurements.films if f.reflectance_measurements and not f.opaque]
    if len(films) != 2:
        raise ValueError(f"{measurements.source or 'measurement set'}: expected two films (over a dark "
                         f"and a light card), found {len(films)}")
    r_s = np.array([measurements.substrate_albedo(f) for f in films])
    order = np.argsort(r_s.mean(axis=1))
    observed = np.array([films[i].reflectance[:, 0] for i in order])
    return observed, r_s[order], films[order[0]].instrument(measurements.n).channels[0]


class RadiativeTransferTintModel:
    """bayespig's radiative-transfer model as a tint model: ``u = a``, ``E = tau``.

    Parameters
    ----------
    instrument : str or Instrument
        The films' instrument (e.g. ``"8d-sce"``); its look-up table is loaded from the cache
        (built on first use; with a ``g`` axis when ``g != 0``).
    table : LookupTable, optional
        The instrument's table (isotropic, or with a ``g`` axis covering ``g``).
    settings : FitSettings, optional
        Point-fit settings; default a starting grid twice as fine as the default (the
        default grid can miss the narrow method-4 valley of white-rich films).
    g : float
        Henyey-Greenstein parameter of every film [-], fixed (default 0, isotropic). The
        mixing rule adds scattering coefficients, so a common ``g`` is also the mixture's.
    """

    def __init__(self, instrument, table=None, settings=None, g=0.0):
        from ..fit import FitSettings
        from ..table import load_table

        self.g = float(g)
        self.name = "bayespig" if self.g == 0.0 else f"bayespig (g = {self.g:g})"
        self.table = table if table is not None else load_table(
            instrument, g="isotropic" if self.g == 0.0 else "free", progress=False)
        if self.g != 0.0 and not self.table.free_g:
            raise ValueError(f"g = {self.g:g} needs a table with a g axis (load_table(..., g='free'))")
        self.settings = settings or FitSettings(n_grid_a=64, n_grid_tau=96)
        self.tau_max = float(self.table.settings.tau_nodes[-1])

    def calibrate(self, measurements, r_s=None):
        """Method-4 point fit: ``a`` and ``tau`` per wavelength (:class:`FilmCalibration`).

        ``r_s`` (shape (2, n_wavelengths), dark card first) replaces the cards' albedos
        converted from air (e.g. to compare with using the air values directly).

        Wavelengths whose fit leaves a relative rms above :data:`REFIT_RMS` are refitted
        from other starts (the opaque limit ``tau = inf`` fitted alone for ``a``, and local
        fits started from each neighbouring wavelength's estimate); the best of all by the
        same objective is kept. :func:`bayespig.fit.fit_problem` can stop far from the
        minimum for nearly opaque films measured with the dark card brighter than the light
        one (noise), e.g. Revigo 06A at 590 nm (rms 0.79 instead of 0.004).
        """
        from dataclasses import replace

        from ..fit import FitSettings, fit_problem
        from ..likelihood import Problem

        problem = Problem.from_measurements(measurements, method="method4")
        observed, card_r_s, _ = black_white_pair(measurements)
        if r_s is None:
            r_s = card_r_s
        else:
            r_s = np.asarray(r_s, dtype=float)
            if r_s.shape != card_r_s.shape or not ((r_s >= 0) & (r_s <= 1)).all():
                raise ValueError(f"r_s must have shape {card_r_s.shape} with values in [0, 1]")
            films = list(problem.films)
            for rank, k in enumerate(np.argsort([f.r_s.mean() for f in films])):
                films[k] = replace(films[k], r_s=r_s[rank])
            problem = replace(problem, films=tuple(films))
        tables = {film.instrument: self.table for film in problem.films}
        result = fit_problem(problem, g=self.g, tables=tables, settings=self.settings, warn=False)
        a, tau = result.a.copy(), result.tau[:, 0].copy()

        def cost(a_value, tau_value, i):
            model = self.reflectance(a_value, tau_value, r_s[:, i])
            with np.errstate(divide="ignore", invalid="ignore"):
                value = np.sum((observed[:, i] / model - 1.0) ** 2)
            return value if np.isfinite(value) else np.inf

        for i in np.flatnonzero(result.rms_relative_deviation > REFIT_RMS):
            best = (cost(a[i], tau[i], i), a[i], tau[i])
            opaque = optimize.minimize_scalar(lambda x, i=i: cost(x, np.inf, i), bounds=(0.0, 1.0),
                                              method="bounded", options={"xatol": 1e-9})
            best = min(best, (opaque.fun, float(opaque.x), np.inf))
            row = _single_row(problem, i)
            for j in (i - 1, i + 1):
                if 0 <= j < a.size:
                    start = (float(np.clip(a[j], 1e-4, 1.0)), float(min(tau[j], 0.5 * self.tau_max)))
                    local = fit_problem(row, g=self.g, tables=tables, settings=FitSettings(start=start),
                                        warn=False)
                    best = min(best, (cost(local.a[0], local.tau[0, 0], i), local.a[0], local.tau[0, 0]))
            _, a[i], tau[i] = best
        tau = np.minimum(tau, self.tau_max)
        rms = np.array([np.sqrt(cost(a[i], tau[i], i) / 2.0) for i in range(a.size)])
        return FilmCalibration(a, tau, rms)

    def reflectance(self, intensive, extensive, r_s):
        """Predicted reflectance [1] of films with ``a = intensive``, ``tau = extensive`` over ``r_s``."""
        tau = np.where(np.asarray(extensive) > self.tau_max, np.inf, extensive)
        return self.table(a=np.clip(intensive, 0.0, 1.0), tau=tau, g=self.g, r_s=r_s)[..., 0]


class KubelkaMunkTintModel:
    """Two-constant Kubelka-Munk with Saunderson correction: ``u = K/S``, ``E = S*X``.

    Parameters
    ----------
    specular : {"excluded", "included"}
        SCE or SCI measurements.
    refractive_index : float
        Binder index for the Saunderson constants (:func:`bayespig.kubelka_munk.saunderson_constants`).
    theta_i : float
        Incidence angle [deg] (8 for 8/d).
    k1, k2 : float, optional
        Override the Saunderson constants.
    """

    name = "kubelka-munk"

    def __init__(self, specular, refractive_index=1.45, theta_i=8.0, k1=None, k2=None):
        if specular not in ("excluded", "included"):
            raise ValueError(f"specular must be 'excluded' or 'included', got {specular!r}")
        d1, d2 = km.saunderson_constants(refractive_index, theta_i)
        self.specular = specular
        self.k1 = d1 if k1 is None else float(k1)
        self.k2 = d2 if k2 is None else float(k2)

    def calibrate(self, measurements):
        """Black/white calibration: ``K/S`` and ``S*X`` per wavelength (:class:`FilmCalibration`)."""
        observed, r_s, _ = black_white_pair(measurements)
        film = km.calibrate_film(observed[0], observed[1], r_s[0], r_s[1], specular=self.specular,
                                 k1=self.k1, k2=self.k2)
        predicted = self.reflectance(film.k_over_s, film.SX, r_s)
        rms = np.sqrt(np.mean((observed / predicted - 1.0) ** 2, axis=0))
        return FilmCalibration(film.k_over_s, film.SX, rms)

    def reflectance(self, intensive, extensive, r_s):
        """Predicted reflectance [1] of films with ``K/S = intensive``, ``S*X = extensive`` over ``r_s``."""
        R_i = km.layer_reflectance(intensive, 1.0, extensive, r_s)
        return km.saunderson_to_measured(np.minimum(R_i, 1.0), self.k1, self.k2, specular=self.specular)


def _single_row(problem, index):
    """The problem restricted to one wavelength."""
    from dataclasses import replace

    films = tuple(replace(f, observed=f.observed[index:index + 1], r_s=f.r_s[index:index + 1])
                  for f in problem.films)
    return replace(problem, wavelength_nm=problem.wavelength_nm[index:index + 1], films=films)


def mixture_weight_ratio(u_pigment, u_white, u_tint):
    """``y = (u_B - u_W) / (u_P - u_B)``: the tint's weight ratio ``D_P w_P / (D_W w_W)`` (step 3).

    Parameters
    ----------
    u_pigment, u_white, u_tint : array_like, shape (n_wavelengths,)
        Intensive property (``a`` or ``K/S``) of the pigment, the white and their tint.

    Returns
    -------
    tuple of numpy.ndarray
        ``(y, determined)``: the ratio (>= 0), with ``log y`` interpolated over the index
        where not ``determined`` (``u_P`` ~ ``u_W``, or ``u_B`` outside ``[u_W, u_P]``).

    Raises
    ------
    ValueError
        When no wavelength determines the ratio.
    """
    uP, uW, uB = (np.asarray(v, dtype=float) for v in (u_pigment, u_white, u_tint))
    spread = uP - uW
    tolerance = DEGENERATE_RTOL * (np.abs(uP) + np.abs(uW)) + DEGENERATE_ATOL
    inside = (uB - uW) * np.sign(spread) > 0
    inside &= (uP - uB) * np.sign(spread) > 0
    determined = (np.abs(spread) > tolerance) & inside
    if not determined.any():
        raise ValueError("the tint does not determine the pigment's strength at any wavelength "
                         "(its intensive property never lies between the pigment's and the white's)")
    with np.errstate(divide="ignore", invalid="ignore"):
        y = (uB - uW) / (uP - uB)
    index = np.arange(uP.size)
    log_y = np.interp(index, index[determined], np.log(y[determined]))
    return np.where(determined, y, np.exp(log_y)), determined


@dataclass(frozen=True)
class TintPrediction:
    """A predicted tint (over a dark and a light card) against its measurement.

    Attributes
    ----------
    model : str
    wavelength_nm : numpy.ndarray
    predicted, measured : numpy.ndarray
        Shape (2, n_wavelengths) [1], dark card first.
    thickness : float
        C's thickness relative to the white film's, fitted (the one free scalar).
    intensive, extensive : numpy.ndarray
        Predicted ``u_C`` and ``E_C`` (at the fitted thickness).
    determined : numpy.ndarray
        Bool per wavelength: B fixed the weight ratio there (else interpolated).
    delta_E : numpy.ndarray
        CIEDE2000 over the dark and the light card, shape (2,).
    rms_relative_deviation : float
        ``sqrt(mean((measured / predicted - 1)^2))`` over both cards and all wavelengths.
    """

    model: str
    wavelength_nm: np.ndarray
    predicted: np.ndarray
    measured: np.ndarray
    thickness: float
    intensive: np.ndarray
    extensive: np.ndarray
    determined: np.ndarray
    delta_E: np.ndarray
    rms_relative_deviation: float


def _mix_tint(u_P, u_W, E_W, u_B, concentrations_b, concentrations_c, white_concentration):
    """Steps 2-4 of the protocol: C's intensive ``u_C`` and extensive per unit thickness ``k_C``."""
    (dPB, dWB), (dPC, dWC) = concentrations_b, concentrations_c
    w_W = E_W / white_concentration
    y_B, determined = mixture_weight_ratio(u_P, u_W, u_B)
    w_P = y_B * dWB * w_W / dPB
    k_C = dPC * w_P + dWC * w_W  # per unit thickness of W (inf where W hides its card)
    y_C = y_B * (dPC / dWC) * (dWB / dPB)  # C's weight ratio D_P w_P / (D_W w_W)
    u_C = (y_C * u_P + u_W) / (y_C + 1.0)
    return u_C, k_C, determined


def _fit_thickness(model, u_C, k_C, measured, r_s):
    """The one free scalar: ``log h`` minimising C's squared relative deviations; and the prediction."""

    def predicted(log_h):
        return model.reflectance(u_C, np.exp(log_h) * k_C, r_s)

    def cost(log_h):
        with np.errstate(divide="ignore", invalid="ignore"):
            value = np.sum((measured / predicted(log_h) - 1.0) ** 2)
        return value if np.isfinite(value) else 1e300

    lo, hi = np.log(THICKNESS_BOUNDS)
    grid = np.linspace(lo, hi, 41)
    start = grid[int(np.argmin([cost(x) for x in grid]))]
    step = grid[1] - grid[0]
    found = optimize.minimize_scalar(cost, bounds=(max(lo, start - step), min(hi, start + step)),
                                     method="bounded", options={"xatol": 1e-6})
    return float(found.x), predicted(float(found.x))


def predict_tint(model, *, masstone, white, tint_b, tint_c, concentrations_b, concentrations_c,
                 white_concentration=1.0, calibrations=None):
    """Predict tint C from masstone A, white W and tint B, with one free thickness for C.

    Parameters
    ----------
    model : RadiativeTransferTintModel or KubelkaMunkTintModel
    masstone, white, tint_b, tint_c : MeasurementSet
        Each one film over a dark and a light card (same wavelengths).
    concentrations_b, concentrations_c : tuple of float
        ``(D_P, D_W)`` of the tints [relative, appendix A2], e.g. mass fractions.
    white_concentration : float
        ``D_W`` of the white film, on the same scale.
    calibrations : dict, optional
        Cache ``id(measurements) -> FilmCalibration`` shared between calls (the masstone and
        white are calibrated once per model).

    Returns
    -------
    TintPrediction

    References
    ----------
    Ershov, Voloboy & Pozdnyakov (2023), section 2 and appendix A2; see the module docstring.
    """
    cache = {} if calibrations is None else calibrations

    def calibrate(ms):
        key = (model.name, id(ms))
        if key not in cache:
            cache[key] = model.calibrate(ms)
        return cache[key]

    for name, c in (("concentrations_b", concentrations_b), ("concentrations_c", concentrations_c)):
        c = np.asarray(c, dtype=float)
        if c.shape != (2,) or not np.isfinite(c).all() or (c <= 0).any():
            raise ValueError(f"{name} must be two positive numbers (pigment, white), got {c}")
    if not (np.isfinite(white_concentration) and white_concentration > 0):
        raise ValueError(f"white_concentration must be > 0, got {white_concentration}")
    A, W, B = calibrate(masstone), calibrate(white), calibrate(tint_b)
    u_C, k_C, determined = _mix_tint(A.intensive, W.intensive, W.extensive, B.intensive,
                                     concentrations_b, concentrations_c, white_concentration)
    measured, r_s, _ = black_white_pair(tint_c)
    log_h, prediction = _fit_thickness(model, u_C, k_C, measured, r_s)
    wavelength_nm = np.asarray(tint_c.wavelength_nm, dtype=float)
    lab_predicted = colorimetry.reflectance_to_Lab(np.clip(prediction, 0.0, None), wavelength_nm)
    lab_measured = colorimetry.reflectance_to_Lab(measured, wavelength_nm)
    return TintPrediction(
        model=model.name,
        wavelength_nm=wavelength_nm,
        predicted=prediction,
        measured=measured,
        thickness=float(np.exp(log_h)),
        intensive=u_C,
        extensive=np.exp(log_h) * k_C,
        determined=determined,
        delta_E=colorimetry.delta_E2000(lab_predicted, lab_measured),
        rms_relative_deviation=float(np.sqrt(np.mean((measured / prediction - 1.0) ** 2))),
    )


@dataclass(frozen=True)
class TintPosterior:
    """Posterior predictive of tint C's colour (bayespig), with its credible region.

    Attributes
    ----------
    lab_draws : numpy.ndarray
        Shape (n_draws, 2, 3): CIELAB of the predicted C over the dark and light card, one row
        per posterior draw of A, W, B (C's thickness refitted per draw).
    lab_measured : numpy.ndarray
        Shape (2, 3).
    thickness : numpy.ndarray
        Shape (n_draws,): C's fitted thickness per draw (relative to W).
    delta_E : numpy.ndarray
        Shape (n_draws, 2): CIEDE2000 of each draw against the measurement.
    inside : numpy.ndarray
        Shape (2,), bool: the measured colour lies in the ``probability`` credible region.
    probability : float
    """

    lab_draws: np.ndarray
    lab_measured: np.ndarray
    thickness: np.ndarray
    delta_E: np.ndarray
    inside: np.ndarray
    probability: float


def credible_region_contains(draws, point, probability=0.9):
    """Whether ``point`` lies in the ``probability`` credible region of 3-D ``draws``.

    The region is the set of points whose Mahalanobis distance from the draws' mean (with their
    covariance) is at most the ``probability`` quantile of the draws' own distances: an
    ellipsoid holding that fraction of the draws (exact for Gaussian draws, and for any
    elliptical distribution).

    Parameters
    ----------
    draws : array_like, shape (n, 3)
    point : array_like, shape (3,)
    probability : float

    Returns
    -------
    bool
    """
    draws = np.asarray(draws, dtype=float)
    if draws.ndim != 2 or draws.shape[0] <= draws.shape[1] + 1:
        raise ValueError(f"draws must have shape (n, d) with n > d + 1, got {draws.shape}")
    if not 0.0 < probability < 1.0:
        raise ValueError(f"probability must lie in (0, 1), got {probability}")
    mean = draws.mean(axis=0)
    precision = np.linalg.pinv(np.cov(draws, rowvar=False))
    centred = draws - mean
    d2 = np.einsum("ni,ij,nj->n", centred, precision, centred)
    offset = np.asarray(point, dtype=float) - mean
    return bool(offset @ precision @ offset <= np.quantile(d2, probability))


def _posterior_draws(idata, n_draws, rng):
    """``a``, ``tau`` draws (n_draws, n_wavelengths): whole spectra, draw ``k`` at every wavelength.

    Draw ``k`` of every wavelength is a draw from the joint posterior of the spectrum, both when
    the wavelengths were sampled independently and when a card factor couples them
    (``infer(..., substrate_sd=...)``).
    """
    a = idata.posterior["a"].values  # (chain, draw, wavelength)
    tau = idata.posterior["tau"].values
    flat_a = a.reshape(-1, a.shape[-1])
    flat_tau = tau.reshape(-1, tau.shape[-1])
    pick = rng.integers(0, flat_a.shape[0], size=n_draws)
    return flat_a[pick], flat_tau[pick]


def tint_posterior_predictive(model, posteriors, *, tint_c, concentrations_b, concentrations_c,
                              white_concentration=1.0, n_draws=200, probability=0.9, seed=0):
    """Posterior predictive of tint C over both cards from posteriors of A, W and B (bayespig).

    Each draw takes a whole spectrum of ``a`` and ``tau`` of the masstone, the white and tint B
    from their posteriors (:func:`bayespig.inference.infer`, method 4, with or without card
    factors), runs steps 2-4 of the protocol, and refits C's thickness (the one free scalar)
    on C's spectra.

    Parameters
    ----------
    model : RadiativeTransferTintModel
    posteriors : dict
        ``"masstone"``, ``"white"``, ``"tint_b"`` -> arviz.InferenceData with posterior ``a`` and
        ``tau`` over (chain, draw, wavelength).
    tint_c : MeasurementSet
    concentrations_b, concentrations_c, white_concentration
        As in :func:`predict_tint`.
    n_draws : int
    probability : float
        Credible level of the colour region (:func:`credible_region_contains`).
    seed : int
        Seeds ``numpy.random.default_rng`` for the choice of draws.

    Returns
    -------
    TintPosterior
    """
    missing = {"masstone", "white", "tint_b"} - set(posteriors)
    if missing:
        raise ValueError(f"posteriors lacks {', '.join(sorted(missing))}")
    rng = np.random.default_rng(seed)
    drawn = {name: _posterior_draws(posteriors[name], n_draws, rng) for name in ("masstone", "white", "tint_b")}
    measured, r_s, _ = black_white_pair(tint_c)
    wavelength_nm = np.asarray(tint_c.wavelength_nm, dtype=float)
    lab_measured = colorimetry.reflectance_to_Lab(measured, wavelength_nm)
    spectra, thickness = np.empty((n_draws,) + measured.shape), np.empty(n_draws)
    for k in range(n_draws):
        u_C, k_C, _ = _mix_tint(drawn["masstone"][0][k], drawn["white"][0][k], drawn["white"][1][k],
                                drawn["tint_b"][0][k], concentrations_b, concentrations_c, white_concentration)
        log_h, spectra[k] = _fit_thickness(model, u_C, k_C, measured, r_s)
        thickness[k] = np.exp(log_h)
    lab_draws = colorimetry.reflectance_to_Lab(np.clip(spectra, 0.0, None), wavelength_nm)
    inside = np.array([credible_region_contains(lab_draws[:, j], lab_measured[j], probability)
                       for j in range(measured.shape[0])])
    return TintPosterior(lab_draws, lab_measured, thickness,
                         colorimetry.delta_E2000(lab_draws, lab_measured[None]), inside, probability)


@dataclass(frozen=True)
class ModelErrorRegion:
    """A tint's credible colour region widened by the model error seen on the other tints.

    Attributes
    ----------
    covariance : numpy.ndarray
        Shape (3, 3): second moment (about zero) of the other series' CIELAB residuals,
        measured minus posterior-mean prediction, over both cards [ΔE units²].
    inside : numpy.ndarray
        Shape (2,), bool: the measured colour lies in the widened ``probability`` region (dark,
        light card).
    rms : float
        ``sqrt(trace(covariance))``: the rms CIELAB distance of those residuals.
    n_residuals : int
        Residual vectors behind ``covariance``.
    """

    covariance: np.ndarray
    inside: np.ndarray
    rms: float
    n_residuals: int


def cross_validated_model_error(posteriors, *, probability=0.9, seed=0):
    """Credible colour regions of every tint with the model error of the *other* tints added.

    The posterior predictive of :func:`tint_posterior_predictive` carries the uncertainty of
    the calibration films only: where the mixing rule or the layer model is wrong, the region
    is far too small. Leave one series out: the model error of a series is taken as Gaussian
    in CIELAB with zero mean and the second moment ``Sigma`` of the residuals (measured minus
    posterior-mean predicted colour, both cards) of every other series, so a systematic
    offset counts as error too. Draws ``lab + N(0, Sigma)`` then define the region as in
    :func:`credible_region_contains`. Under exchangeable series with Gaussian errors the
    regions cover the measured colour at their nominal level (tested on simulated
    residuals); the series' own measurement never enters its own region.

    Parameters
    ----------
    posteriors : dict
        Series -> :class:`TintPosterior` (at least 3 series).
    probability : float
    seed : int
        Seeds ``numpy.random.default_rng`` for the model-error draws.

    Returns
    -------
    dict
        Series -> :class:`ModelErrorRegion`.
    """
    names = list(posteriors)
    if len(names) < 3:
        raise ValueError(f"cross_validated_model_error needs at least 3 series, got {len(names)}")
    residuals = {name: post.lab_measured - post.lab_draws.mean(axis=0) for name, post in posteriors.items()}
    rng = np.random.default_rng(seed)
    out = {}
    for name in names:
        others = np.concatenate([residuals[other] for other in names if other != name])
        covariance = others.T @ others / others.shape[0]
        post = posteriors[name]
        n_draws, n_cards = post.lab_draws.shape[:2]
        inside = np.empty(n_cards, dtype=bool)
        for card in range(n_cards):
            widened = post.lab_draws[:, card] + rng.multivariate_normal(np.zeros(3), covariance, size=n_draws)
            inside[card] = credible_region_contains(widened, post.lab_measured[card], probability)
        out[name] = ModelErrorRegion(covariance, inside, float(np.sqrt(np.trace(covariance))), others.shape[0])
    return out
