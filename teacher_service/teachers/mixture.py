"""What the two Gaussian-mixture teachers (ALP-GMM and Covar-GMM) share: their fit parameters, the
fit itself (mixtures of k = min..max components, the lowest AIC kept), a fitted mixture prepared for
sampling tasks, and the teacher that requests fits, installs them and saves them."""

from __future__ import annotations

import functools
from abc import abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from pydantic import Field, model_validator
from typing_extensions import Self

from common.client.task_space import TaskSpace
from teacher_service.teachers.base import FitJob, Teacher
from teacher_service.teachers.draws import FIT_STREAM, indexed_seed, standard_normals
from teacher_service.teachers.params import TeacherParams
from teacher_service.teachers.state import INT, StateField

MAX_FIT_RATE = 2000
MAX_COMPONENTS = 16
MAX_EM_INITS = 5
"""Together these bound one fit: at most 2,000 points, 16 candidate sizes, 5 EM restarts each."""


class MixtureParams(TeacherParams):
    """What the two Gaussian-mixture teachers share: how often they fit and what each fit tries."""

    fit_rate: int = Field(default=250, ge=2, le=MAX_FIT_RATE)
    """Results between two mixture fits; the first ``fit_rate`` tasks are uniform (bootstrap)."""
    random_task_ratio: float = Field(default=0.2, ge=0.0, le=1.0)
    """Share of tasks drawn uniformly after the bootstrap, so new progress niches are still found."""
    min_components: int = Field(default=2, ge=1, le=MAX_COMPONENTS)
    """Fewest Gaussians tried per fit."""
    max_components: int = Field(default=10, ge=1, le=MAX_COMPONENTS)
    """Most Gaussians tried per fit; the candidate with the lowest AIC wins."""
    nb_em_init: int = Field(default=1, ge=1, le=MAX_EM_INITS)
    """EM restarts per candidate mixture."""

    @model_validator(mode="after")
    def _components_fit(self) -> Self:
        if self.min_components > self.max_components:
            raise ValueError(
                f"min_components ({self.min_components}) cannot exceed max_components ({self.max_components})"
            )
        if self.max_components > self.fit_rate:
            raise ValueError(
                f"max_components ({self.max_components}) cannot exceed fit_rate ({self.fit_rate}): "
                "each fit sees fit_rate points"
            )
        return self


@dataclass(frozen=True)
class MixtureFit:
    """The output of one fit job: the chosen mixture over (task features, ALP)."""

    index: int
    weights: np.ndarray
    means: np.ndarray
    covariances: np.ndarray
    aic_by_components: dict[int, float] = field(default_factory=dict)

    @classmethod
    def from_data(cls, data: Mapping[str, Any], width: int) -> MixtureFit:
        """The fit that ``export_fit`` wrote as ``data``, checked to be over ``width`` coordinates."""
        weights = np.array(data["weights"], dtype=np.float64)
        means = np.array(data["means"], dtype=np.float64)
        covariances = np.array(data["covariances"], dtype=np.float64)
        components = len(weights)
        if means.shape != (components, width) or covariances.shape != (components, width, width):
            raise ValueError(
                f"a mixture of {components} components over {width} coordinates needs means of shape "
                f"{(components, width)} and covariances of shape {(components, width, width)}, "
                f"got {means.shape} and {covariances.shape}"
            )
        aics = {int(k): float(aic) for k, aic in data["aic_by_components"]}
        return cls(int(data["index"]), weights, means, covariances, aics)


def fit_mixture(index: int, points: np.ndarray, components: range, nb_em_init: int, random_state: int) -> MixtureFit:
    """Fit one mixture per candidate size and keep the lowest AIC (ties go to fewer components).

    scikit-learn is imported here, in the fit process, rather than with the module: it is most of a
    service's import time (~2.5 s of ~4 s on a loaded machine), and the service itself never fits."""
    from sklearn.mixture import GaussianMixture

    with np.errstate(under="ignore"):
        mixtures = {
            k: GaussianMixture(
                n_components=k, covariance_type="full", n_init=nb_em_init, random_state=random_state
            ).fit(points)
            for k in components
        }
        aics = {k: float(mixture.aic(points)) for k, mixture in mixtures.items()}
    best = mixtures[min(aics, key=aics.__getitem__)]
    return MixtureFit(index, best.weights_, best.means_, best.covariances_, aics)


@dataclass(frozen=True)
class MixtureSampler:
    """An installed mixture, prepared for sampling task features: only the first ``task_dims``
    coordinates are drawn, and components are picked in proportion to their ``scores``."""

    fit: MixtureFit
    choice_cdf: np.ndarray
    task_means: np.ndarray
    task_cholesky: np.ndarray

    @classmethod
    def prepare(cls, fit: MixtureFit, scores: np.ndarray, task_dims: int) -> MixtureSampler:
        """``scores`` are non-negative, one per component; the reference codes pick a component
        uniformly when none is positive."""
        total = scores.sum()
        probabilities = scores / total if total > 0 else np.full(len(scores), 1.0 / len(scores))
        return cls(
            fit=fit,
            choice_cdf=np.cumsum(probabilities),
            task_means=fit.means[:, :task_dims],
            task_cholesky=np.linalg.cholesky(fit.covariances[:, :task_dims, :task_dims]),
        )

    @property
    def probabilities(self) -> np.ndarray:
        return np.diff(self.choice_cdf, prepend=0.0)

    def draw(self, choice: np.ndarray, normal_quantiles: np.ndarray) -> np.ndarray:
        """Task features from uniforms: ``choice`` (n,) picks components, ``normal_quantiles``
        (n, d) become standard normals by the inverse CDF, so each draw uses a fixed count."""
        component = np.minimum(np.searchsorted(self.choice_cdf, choice, side="right"), len(self.choice_cdf) - 1)
        normals = standard_normals(normal_quantiles)
        offsets = np.einsum("nij,nj->ni", self.task_cholesky[component], normals)
        features: np.ndarray = self.task_means[component] + offsets
        return features


class MixtureTeacher(Teacher):
    """What the two Gaussian-mixture teachers share: a fit is a ``MixtureFit`` over the task
    features and ``extra_coordinates`` more (ALP; or time and reward), and the newest one installed
    is turned by ``_prepare`` into the sampler that draws tasks."""

    params: MixtureParams
    extra_coordinates: int
    state_fields: ClassVar[tuple[StateField, ...]] = (
        StateField("fits_requested", INT),
        StateField("fits_installed", INT),
    )

    def __init__(self, space: TaskSpace, seed: int, params: MixtureParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        self._width = len(space) + self.extra_coordinates
        self._sampler: MixtureSampler | None = None
        self.fits_requested = 0
        self.fits_installed = 0

    @abstractmethod
    def _prepare(self, fit: MixtureFit) -> MixtureSampler:
        """The sampler for ``fit``: how this teacher scores its components."""

    @abstractmethod
    def _fit_points(self, start: int, stop: int) -> np.ndarray:
        """The rows of results ``start`` to ``stop`` (exclusive) that a fit sees."""

    def refit_job(self, index: int) -> FitJob:
        """Fit ``index`` sees batch ``index``: the ``fit_rate`` results before it fell due."""
        if not 0 <= index < self.fits_requested:
            raise ValueError(f"fit {index} has not fallen due ({self.fits_requested} have)")
        rate = self.params.fit_rate
        run = functools.partial(
            fit_mixture,
            index,
            self._fit_points(index * rate, (index + 1) * rate),
            range(self.params.min_components, self.params.max_components + 1),
            self.params.nb_em_init,
            indexed_seed(self.seed, FIT_STREAM, index),
        )
        return FitJob(index=index, run=run)

    def install(self, fitted: MixtureFit) -> None:
        if not isinstance(fitted, MixtureFit):
            raise TypeError(f"expected the MixtureFit returned by a FitJob, got {type(fitted).__name__}")
        if self._sampler is not None and fitted.index <= self._sampler.fit.index:
            raise ValueError(f"fit {fitted.index} is stale: fit {self._sampler.fit.index} is installed")
        self._sampler = self._prepare(fitted)
        self.fits_installed += 1

    def export_fit(self, fitted: MixtureFit) -> dict[str, Any]:
        return {
            "index": fitted.index,
            "weights": fitted.weights.tolist(),
            "means": fitted.means.tolist(),
            "covariances": fitted.covariances.tolist(),
            "aic_by_components": [[k, aic] for k, aic in fitted.aic_by_components.items()],
        }

    def import_fit(self, data: Mapping[str, Any]) -> MixtureFit:
        return MixtureFit.from_data(data, self._width)

    def _export(self) -> dict[str, Any]:
        """The fit counters and the installed model (a kind adds its history around them)."""
        return {**super()._export(), "model": None if self._sampler is None else self.export_fit(self._sampler.fit)}

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        super()._import(state, history)
        model = state["model"]
        self._sampler = None if model is None else self._prepare(self.import_fit(model))
