"""Named scenario parameters and their flat layout ``X`` of shape (B, D).

The estimation engine sees one scenario realisation as a flat float64 row of
length ``D``; everything else sees it by name. The layout is vehicle-major,
four coordinates per vehicle, then the learned-driver block ``xi`` (the
learned drivers' per-rollout parameters: the ``Dxi = 404`` numbers of the
driver network's last layer, in the order of :mod:`avrisk.agents.drivers.xi`;
empty when no vehicle is a learned driver), then the learned drivers' action
innovations when the scenario puts them in ``X`` (``actions: sampled_in_x``:
``Dn = 2 T C`` standard normals, step-major, then the ``C`` learned drivers
in slot order, then acceleration and steering; empty otherwise)::

    veh0.s, veh0.t, veh0.heading, veh0.speed, veh1.s, ..., veh{A-1}.speed,
    xi.0, ..., xi.{Dxi-1}, noise.0, ..., noise.{Dn-1}

=============  ======  ===================================================
coordinate     unit    meaning
=============  ======  ===================================================
``vehJ.s``     m       along the road, relative to slot J's ``offset``
``vehJ.t``     m       lateral offset from the centre of slot J's lane
``vehJ.heading`` deg   heading relative to the lane direction (ccw > 0)
``vehJ.speed`` m/s     initial speed
``xi.K``       -       last-layer weights of the environment driver network
``noise.K``    -       standard-normal innovation of a learned driver's action
=============  ======  ===================================================

The column names double as Parquet column names.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from avrisk.scenario.scene import VEHICLE_FIELDS
from avrisk.scenario.spec import ScenarioSpec

FloatArray = NDArray[np.float64]

#: Unit of each per-vehicle coordinate, as stored in ``X`` and in Parquet.
FIELD_UNITS: dict[str, str] = {"s": "m", "t": "m", "heading": "deg", "speed": "m/s"}


#: Prefix of the driver-network columns ``xi.K`` of ``X``.
XI_PREFIX = "xi."
#: Prefix of the learned drivers' action innovations ``noise.K`` of ``X``.
NOISE_PREFIX = "noise."


@dataclass(frozen=True)
class ParamLayout:
    """Column layout of a flat scenario sample ``X`` of shape (B, D).

    Parameters
    ----------
    n_vehicles : int
        Number of vehicles ``A`` (ego included).
    xi_dim : int, default=0
        Length of the learned-driver parameter block ``xi`` (0: none yet).
    noise_dim : int, default=0
        Length of the learned drivers' innovations block (0: none in ``X``).

    Attributes
    ----------
    columns : tuple of str
        The ``D`` column names, in order.
    dim : int
        ``D = 4 A + xi_dim + noise_dim``.

    Examples
    --------
    >>> layout = ParamLayout(n_vehicles=2)
    >>> layout.columns[:5]
    ('veh0.s', 'veh0.t', 'veh0.heading', 'veh0.speed', 'veh1.s')
    >>> layout.index("veh1.speed")
    7
    """

    n_vehicles: int
    xi_dim: int = 0
    noise_dim: int = 0
    _index: dict[str, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.n_vehicles < 1:
            raise ValueError(f"n_vehicles must be >= 1; got {self.n_vehicles}")
        if self.xi_dim < 0:
            raise ValueError(f"xi_dim must be >= 0; got {self.xi_dim}")
        if self.noise_dim < 0 or (self.noise_dim and not self.xi_dim):
            raise ValueError(
                f"noise_dim must be >= 0, and 0 without learned drivers (xi_dim 0); "
                f"got noise_dim={self.noise_dim}, xi_dim={self.xi_dim}"
            )
        object.__setattr__(
            self, "_index", {name: i for i, name in enumerate(self.columns)}
        )

    @classmethod
    def from_spec(cls, spec: ScenarioSpec, xi_dim: int | None = None) -> ParamLayout:
        """The layout of a scenario's ``X``.

        Parameters
        ----------
        spec : ScenarioSpec
        xi_dim : int or None
            Length of the learned drivers' parameter block; required when any
            vehicle is a learned driver (:attr:`ScenarioSpec.has_learned_drivers`),
            unused otherwise. :func:`avrisk.assembly.param_layout` passes the
            driver network's. The innovations block follows from the spec
            (:attr:`ScenarioSpec.noise_dim`).

        Raises
        ------
        ValueError
            If the scenario has learned drivers and ``xi_dim`` is None.
        """
        if not spec.has_learned_drivers:
            return cls(n_vehicles=spec.n_vehicles)
        if xi_dim is None:
            raise ValueError(
                f"scenario {spec.name!r} has learned drivers: pass xi_dim, the "
                "length of their parameter block (avrisk.assembly.param_layout does)"
            )
        return cls(n_vehicles=spec.n_vehicles, xi_dim=xi_dim, noise_dim=spec.noise_dim)

    @cached_property
    def columns(self) -> tuple[str, ...]:
        """Column names ``vehJ.<field>``, ``xi.K`` then ``noise.K``, length ``D``."""
        veh = [f"veh{j}.{f}" for j in range(self.n_vehicles) for f in VEHICLE_FIELDS]
        xi = [f"{XI_PREFIX}{k}" for k in range(self.xi_dim)]
        return tuple(veh + xi + [f"{NOISE_PREFIX}{k}" for k in range(self.noise_dim)])

    @property
    def dim(self) -> int:
        """Dimension ``D`` of one flat sample."""
        return len(VEHICLE_FIELDS) * self.n_vehicles + self.xi_dim + self.noise_dim

    @property
    def xi_slice(self) -> slice:
        """Columns of the ``xi`` block."""
        start = len(VEHICLE_FIELDS) * self.n_vehicles
        return slice(start, start + self.xi_dim)

    @property
    def noise_slice(self) -> slice:
        """Columns of the innovations block."""
        start = self.xi_slice.stop
        return slice(start, start + self.noise_dim)

    def unit(self, column: str) -> str:
        """Unit of a column (``"m"``, ``"deg"``, ``"m/s"`` or ``"-"``)."""
        self.index(column)
        if column.startswith((XI_PREFIX, NOISE_PREFIX)):
            return "-"
        return FIELD_UNITS[column.split(".", 1)[1]]

    def units(self) -> dict[str, str]:
        """Unit of every column, by name (see :meth:`unit`)."""
        return {c: self.unit(c) for c in self.columns}

    def index(self, column: str) -> int:
        """Position of a named column in ``X``.

        Raises
        ------
        KeyError
            If the name is not a column of this layout.
        """
        try:
            return self._index[column]
        except KeyError:
            raise KeyError(
                f"{column!r} is not a scenario column; columns look like "
                f"'veh0.s' .. 'veh{self.n_vehicles - 1}.speed'"
            ) from None

    def field_columns(self, name: str) -> NDArray[np.intp]:
        """Indices of ``veh0.<name>, ..., veh{A-1}.<name>`` in ``X``, shape (A,)."""
        k = VEHICLE_FIELDS.index(name)
        return np.arange(self.n_vehicles) * len(VEHICLE_FIELDS) + k


@dataclass(frozen=True)
class ScenarioParams:
    """One batch of scenario realisations, by name.

    All arrays are float64 with leading batch dimension ``B``; the vehicle
    arrays are (B, A) with vehicle 0 the ego.

    Attributes
    ----------
    s : ndarray of shape (B, A)
        Position along the road relative to the slot offset [m].
    t : ndarray of shape (B, A)
        Lateral offset from the lane centre, positive left [m].
    heading : ndarray of shape (B, A)
        Heading relative to the lane direction, ccw positive [deg].
    speed : ndarray of shape (B, A)
        Initial speed [m/s].
    xi : ndarray of shape (B, Dxi)
        Learned-driver parameters (``Dxi = 0`` for IDM+MOBIL drivers).
    noise : ndarray of shape (B, Dn)
        The learned drivers' action innovations (``Dn = 0`` unless the
        scenario puts them in ``X``).
    """

    s: FloatArray
    t: FloatArray
    heading: FloatArray
    speed: FloatArray
    xi: FloatArray
    noise: FloatArray

    def __post_init__(self) -> None:
        shape = np.shape(self.s)
        for name in VEHICLE_FIELDS:
            if np.shape(getattr(self, name)) != shape or len(shape) != 2:
                raise ValueError(
                    f"ScenarioParams.{name} must have shape (B, A) = {shape}; got "
                    f"{np.shape(getattr(self, name))}"
                )
        for name in ("xi", "noise"):
            block = getattr(self, name)
            if np.ndim(block) != 2 or np.shape(block)[0] != shape[0]:
                raise ValueError(
                    f"ScenarioParams.{name} must have shape (B, D{name}) with "
                    f"B = {shape[0]}; got {np.shape(block)}"
                )

    @property
    def batch_size(self) -> int:
        """Number of realisations ``B``."""
        return int(np.shape(self.s)[0])

    @property
    def n_vehicles(self) -> int:
        """Number of vehicles ``A``."""
        return int(np.shape(self.s)[1])

    @property
    def layout(self) -> ParamLayout:
        """The flat layout these parameters map to."""
        return ParamLayout(
            self.n_vehicles, int(np.shape(self.xi)[1]), int(np.shape(self.noise)[1])
        )

    def __len__(self) -> int:
        return self.batch_size

    def __getitem__(
        self, rows: slice | NDArray[np.integer] | list[int]
    ) -> ScenarioParams:
        """Select realisations (rows) by slice, index list or boolean mask."""
        return ScenarioParams(
            **{
                name: getattr(self, name)[rows]
                for name in (*VEHICLE_FIELDS, "xi", "noise")
            }
        )

    @classmethod
    def from_flat(cls, x: FloatArray, layout: ParamLayout) -> ScenarioParams:
        """Unpack a flat sample.

        Parameters
        ----------
        x : ndarray of shape (B, D)
            Flat samples in the column order of ``layout``.
        layout : ParamLayout

        Returns
        -------
        ScenarioParams
        """
        x = np.asarray(x, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != layout.dim:
            raise ValueError(
                f"X must have shape (B, {layout.dim}) for {layout.n_vehicles} "
                f"vehicles, xi_dim={layout.xi_dim} and noise_dim={layout.noise_dim}; "
                f"got {x.shape}"
            )
        return cls(
            **{name: x[:, layout.field_columns(name)] for name in VEHICLE_FIELDS},
            xi=x[:, layout.xi_slice],
            noise=x[:, layout.noise_slice],
        )

    def to_flat(self) -> FloatArray:
        """Pack into a flat sample, shape (B, D), float64 (inverse of from_flat)."""
        layout = self.layout
        x = np.empty((self.batch_size, layout.dim), dtype=np.float64)
        for name in VEHICLE_FIELDS:
            x[:, layout.field_columns(name)] = getattr(self, name)
        x[:, layout.xi_slice] = self.xi
        x[:, layout.noise_slice] = self.noise
        return x

    def to_columns(self) -> dict[str, FloatArray]:
        """Named columns ``{"veh0.s": (B,), ...}`` in layout order."""
        x = self.to_flat()
        return {name: x[:, i] for i, name in enumerate(self.layout.columns)}

    @classmethod
    def from_columns(
        cls, columns: Mapping[str, NDArray[np.floating]], layout: ParamLayout
    ) -> ScenarioParams:
        """Rebuild from named columns (e.g. a Parquet table read back).

        Parameters
        ----------
        columns : mapping of str to ndarray of shape (B,)
            Must contain every column of ``layout``; extra keys are ignored.
        layout : ParamLayout

        Raises
        ------
        KeyError
            Naming the first missing column.
        """
        missing = [c for c in layout.columns if c not in columns]
        if missing:
            raise KeyError(
                f"missing scenario column(s) {missing[:4]}"
                + (" ..." if len(missing) > 4 else "")
            )
        x = np.stack(
            [np.asarray(columns[c], dtype=np.float64) for c in layout.columns], axis=1
        )
        return cls.from_flat(x, layout)
