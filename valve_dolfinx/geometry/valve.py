"""Three leaflets joined at the commissures and wrapped onto the root cylinder (SPEC §1).

The valve is described here by plain NumPy arrays (:class:`ValveMesh`), built
serially -- the meshes have a few thousand triangles -- and handed to DOLFINx
by :mod:`valve_dolfinx.geometry.distributed`, which distributes it over MPI.

Conventions
-----------
* Leaflet ``k`` (0, 1, 2 = left-coronary, right-coronary, non-coronary) spans
  ``θ ∈ [2πk/3 - π/3, 2πk/3 + π/3]``; flat abscissa ``x`` (arc length along
  the free-edge direction) maps to ``θ = 2πk/3 + 2x/d`` and height ``y`` to the
  axial coordinate ``z``.  Wrapping a flat sheet onto a cylinder is an isometry,
  so the wrapped native leaflets are stress-free.
* Triangles are counter-clockwise in flat coordinates, so their normal
  ``(x1-x0)×(x2-x0)`` points radially outwards in the wrapped (open) valve: that
  is the **aortic side**, on which the diastolic pressure acts.
* The graft (non-coronary position) has its own flat outline, scaled by
  ``(1+W, 1+H)``.  Its flat coordinates are its stress-free reference; its
  placement in 3-D is a slack initial guess (see :func:`place_graft`).
"""

from __future__ import annotations

import json
import logging
import math
import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from valve_dolfinx.exceptions import MeshError, ParameterError
from valve_dolfinx.geometry.flat_mesh import FlatLeafletMesh, mesh_flat_leaflet
from valve_dolfinx.geometry.outline import (
    GRAFT_TOO_LARGE,
    GRAFT_TOO_SMALL,
    MAX_GRAFT_PCT,
    GraftSize,
    LeafletShape,
)
from valve_dolfinx.io import atomic_write
from valve_dolfinx.setting_fields import check_setting, setting

__all__ = [
    "LEAFLET_NAMES",
    "LEAFLET_TAGS",
    "ATTACHMENT",
    "FREE_EDGE",
    "GRAFT_PLACEMENTS",
    "ValveParameters",
    "LeafletPatch",
    "ValveMesh",
    "build_valve",
    "save_valve_mesh",
    "load_valve_mesh",
    "wrap_flat",
    "place_graft",
]

log = logging.getLogger(__name__)

LEAFLET_NAMES = ("left_coronary", "right_coronary", "non_coronary")
#: cell tag of each leaflet
LEAFLET_TAGS = {name: i + 1 for i, name in enumerate(LEAFLET_NAMES)}
#: facet (edge) tags
ATTACHMENT = 1
FREE_EDGE = 2
#: Leaflet replaced by the graft
GRAFT_POSITION = 2
GRAFT_PLACEMENTS = ("conformal", "billowed")

#: Default target edge length (mm).  The membrane convergence study is in
#: docs/verification.md, the coaptation height's mesh convergence (SPEC §8) in docs/numerics.md.
DEFAULT_MESH_SIZE = 0.8


@dataclass(frozen=True)
class ValveParameters:
    """Everything that defines the valve geometry: each setting's unit and meaning is on its
    field.

    A graft of 0 %/0 % is a pericardial leaflet of native size.  ``graft_placement``
    chooses the slack initial 3-D placement of the graft: ``"conformal"`` lays it onto the
    native leaflet's wrapped surface, ``"billowed"`` additionally bulges it by
    ``billow_mm`` towards the valve axis (the ventricular side of the leaflet) or, if
    negative, away from it (towards the aortic sinus); the loaded result must not depend on
    this choice.
    """

    root_diameter: float = setting(20.0, "mm", "root diameter the flat leaflets are sized on")
    gamma_deg: float = setting(34.0, "deg", "angle γ of the attachment curve "
                               "y = sin²x / tan γ")
    commissure_height: float = setting(5.0, "mm", "height of the straight commissure segments")
    mesh_size: float = setting(DEFAULT_MESH_SIZE, "mm", "target triangle edge length")
    graft_width_pct: float | None = setting(None, "%", "graft width enlargement over the "
                                            "native leaflet (unset: the normal valve)")
    graft_height_pct: float | None = setting(None, "%", "graft height enlargement over the "
                                             "native leaflet (unset: the normal valve)")
    graft_fibre_angle_deg: float = setting(0.0, "deg", "fibre direction of the graft from the "
                                           "circumferential direction")
    graft_placement: str = setting("conformal", "", "initial 3-D placement of the slack "
                                   "graft: 'conformal' or 'billowed'")
    billow_mm: float = setting(2.0, "mm", "bulge of a 'billowed' graft towards the valve "
                               "axis (negative: towards the sinus)")

    def __post_init__(self) -> None:
        if (self.graft_width_pct is None) != (self.graft_height_pct is None):
            raise ParameterError("graft_width_pct and graft_height_pct must both be given "
                                 "(per cent, >= 0) or both be None for the normal valve")
        if self.has_graft:
            for name in ("graft_width_pct", "graft_height_pct"):
                check_setting(self, name, 0.0, MAX_GRAFT_PCT, low_hint=GRAFT_TOO_SMALL,
                              high_hint=GRAFT_TOO_LARGE)
        check_setting(self, "graft_fibre_angle_deg", -90.0, 90.0)
        if self.graft_placement not in GRAFT_PLACEMENTS:
            raise ParameterError(f"graft_placement = {self.graft_placement!r}; "
                                 f"choose one of {GRAFT_PLACEMENTS}")
        shape = self.native_shape()  # validates the outline parameters first
        check_setting(self, "billow_mm", -0.4 * self.root_diameter, 0.4 * self.root_diameter,
                      hint="positive bulges the graft towards the valve axis, negative away")
        shape.check_mesh_size(self.mesh_size)

    @property
    def has_graft(self) -> bool:
        return self.graft_width_pct is not None

    def native_shape(self) -> LeafletShape:
        return LeafletShape(self.root_diameter, self.gamma_deg, self.commissure_height)

    def graft_shape(self) -> LeafletShape:
        if not self.has_graft:
            raise ParameterError("this valve has no graft")
        return LeafletShape(self.root_diameter, self.gamma_deg, self.commissure_height,
                            float(self.graft_width_pct), float(self.graft_height_pct))

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class LeafletPatch:
    """One leaflet inside the valve mesh.

    ``nodes`` maps the leaflet's local node numbers to valve node numbers;
    ``flat`` holds the local nodes' flat (reference) coordinates and
    ``triangles`` the local counter-clockwise triangulation.
    """

    name: str
    tag: int
    shape: LeafletShape
    nodes: np.ndarray
    flat: np.ndarray
    triangles: np.ndarray
    free_edge: np.ndarray  # local node ids, left -> right
    attachment: np.ndarray  # local node ids, left commissure top -> right commissure top
    is_graft: bool = False

    @property
    def midline_free_edge_node(self) -> int:
        """Local id of the free-edge node closest to the midline (x = 0)."""
        return int(self.free_edge[np.argmin(np.abs(self.flat[self.free_edge, 0]))])


@dataclass
class ValveMesh:
    """Serial description of the valve surface mesh (see the module docstring).

    Attributes
    ----------
    points
        ``(N, 3)`` initial placement (mm): wrapped on the ``d``-cylinder.
    cells
        ``(M, 3)`` node ids, counter-clockwise in flat coordinates.
    cell_tags
        ``(M,)`` leaflet tag of each cell (:data:`LEAFLET_TAGS`).
    flat
        ``(M, 3, 2)`` flat reference coordinates of each cell's vertices
        (the stress-free configuration; per cell because commissure nodes
        belong to two leaflets with different flat coordinates).
    fibres
        ``(M, 2)`` unit fibre direction in flat coordinates.
    edges, edge_tags
        Tagged boundary/attachment edges: ``ATTACHMENT`` (lower edge and
        commissures) and ``FREE_EDGE``.
    """

    points: np.ndarray
    cells: np.ndarray
    cell_tags: np.ndarray
    flat: np.ndarray
    fibres: np.ndarray
    edges: np.ndarray
    edge_tags: np.ndarray
    leaflets: tuple[LeafletPatch, ...]
    parameters: ValveParameters = field(default_factory=ValveParameters)

    @property
    def num_nodes(self) -> int:
        return len(self.points)

    @property
    def num_cells(self) -> int:
        return len(self.cells)

    def attachment_nodes(self) -> np.ndarray:
        return np.unique(self.edges[self.edge_tags == ATTACHMENT])

    def leaflet(self, name: str) -> LeafletPatch:
        for patch in self.leaflets:
            if patch.name == name:
                return patch
        raise KeyError(f"no leaflet named {name!r}; leaflets are {LEAFLET_NAMES}")

    def fibres_3d(self, points: np.ndarray | None = None) -> np.ndarray:
        """Unit fibre vectors ``(M, 3)`` pushed forward to a placement (default: ``points``)."""
        J = reference_jacobians(self.points if points is None else points, self.cells, self.flat)
        v = np.einsum("mij,mj->mi", J, self.fibres)
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    def validate(self) -> ValveMesh:
        """Raise :class:`MeshError` if the arrays do not describe a usable valve mesh."""
        n, m = len(self.points), len(self.cells)
        checks = [
            (self.points.ndim == 2 and self.points.shape[1] == 3, "points must be (N, 3)"),
            (np.all(np.isfinite(self.points)), "points contain NaN or infinity"),
            (self.cells.ndim == 2 and self.cells.shape[1] == 3, "cells must be (M, 3) triangles"),
            (m > 0 and self.cells.min() >= 0 and self.cells.max() < n,
             "cells refer to nodes that do not exist"),
            (self.cell_tags.shape == (m,) and set(np.unique(self.cell_tags))
             <= set(LEAFLET_TAGS.values()), "every cell needs a leaflet tag 1, 2 or 3"),
            (self.flat.shape == (m, 3, 2) and np.all(np.isfinite(self.flat)),
             "flat reference coordinates must be finite, (M, 3, 2)"),
            (self.fibres.shape == (m, 2) and np.allclose(np.linalg.norm(self.fibres, axis=1), 1),
             "fibre directions must be unit (M, 2) vectors"),
            (len(np.unique(self.cells)) == n, "some nodes belong to no cell"),
        ]
        for ok, message in checks:
            if not ok:
                raise MeshError(f"broken valve mesh: {message}")
        if np.any(np.sort(self.cells, axis=1)[:, :-1] == np.sort(self.cells, axis=1)[:, 1:]):
            raise MeshError("broken valve mesh: a cell repeats a node")
        flat_area = _signed_area_2d(self.flat)
        if np.any(flat_area <= 1e-12):
            raise MeshError(f"broken valve mesh: {np.sum(flat_area <= 1e-12)} cells are inverted "
                            "or degenerate in the flat reference configuration")
        p = self.points[self.cells]
        area3 = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        if np.any(area3 <= 1e-12):
            raise MeshError(f"broken valve mesh: {np.sum(area3 <= 1e-12)} cells have zero area "
                            "in 3-D")
        return self

    # --- I/O ----------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write all arrays to ``path`` (``.npz``), atomically."""
        return save_valve_mesh(self, path)


# --- the valve mesh file ---------------------------------------------------------------
_LEAFLET_ARRAYS = ("nodes", "flat", "triangles", "free_edge", "attachment")


def save_valve_mesh(valve: ValveMesh, path: str | Path) -> Path:
    """Write a :class:`ValveMesh` to ``.npz`` (reloadable)."""
    path = Path(path).with_suffix(".npz")
    arrays: dict[str, np.ndarray] = {
        "points": valve.points, "cells": valve.cells, "cell_tags": valve.cell_tags,
        "flat": valve.flat, "fibres": valve.fibres, "edges": valve.edges,
        "edge_tags": valve.edge_tags,
    }
    meta = {"parameters": valve.parameters.to_dict(), "leaflets": []}
    for i, patch in enumerate(valve.leaflets):
        meta["leaflets"].append({"name": patch.name, "tag": patch.tag, "is_graft": patch.is_graft,
                                 "shape": {k: getattr(patch.shape, k) for k in (
                                     "root_diameter", "gamma_deg", "commissure_height",
                                     "width_pct", "height_pct")}})
        for key in _LEAFLET_ARRAYS:
            arrays[f"leaflet{i}_{key}"] = getattr(patch, key)
    arrays["meta"] = np.array(json.dumps(meta))

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)

    return atomic_write(path, write)


def load_valve_mesh(path: str | Path) -> ValveMesh:
    """Read a valve mesh written by :func:`save_valve_mesh`, and validate it."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such valve mesh; write the default meshes with "
                                "`valve-dolfinx mesh --out meshes`")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
        meta = json.loads(str(arrays.pop("meta")))
        leaflets = []
        for i, info in enumerate(meta["leaflets"]):
            kw = {key: arrays.pop(f"leaflet{i}_{key}") for key in _LEAFLET_ARRAYS}
            leaflets.append(LeafletPatch(name=info["name"], tag=info["tag"],
                                         shape=LeafletShape(**info["shape"]),
                                         is_graft=info["is_graft"], **kw))
        valve = ValveMesh(**arrays, leaflets=tuple(leaflets),
                          parameters=ValveParameters(**meta["parameters"]))
    except (KeyError, ValueError, TypeError, OSError, EOFError, zipfile.BadZipFile) as err:
        raise MeshError(f"{path} is not a valve mesh written by valve_dolfinx ({err}); "
                        "regenerate it with `valve-dolfinx mesh`") from err
    return valve.validate()


def wrap_flat(flat: np.ndarray, centre_angle: float, diameter: float) -> np.ndarray:
    """Wrap flat points ``(n, 2)`` onto the cylinder of ``diameter`` (isometry)."""
    theta = centre_angle + 2.0 * flat[:, 0] / diameter
    r = 0.5 * diameter
    return np.stack([r * np.cos(theta), r * np.sin(theta), flat[:, 1]], axis=1)


def reference_jacobians(points: np.ndarray, cells: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """Per-cell ``(M, 3, 2)`` map J0 = d(placement)/d(flat) of linear triangles."""
    p = points[cells]
    dx = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]], axis=2)  # (M,3,2)
    dX = np.stack([flat[:, 1] - flat[:, 0], flat[:, 2] - flat[:, 0]], axis=2)  # (M,2,2)
    return dx @ np.linalg.inv(dX)


def _signed_area_2d(tri: np.ndarray) -> np.ndarray:
    a = tri[:, 1] - tri[:, 0]
    b = tri[:, 2] - tri[:, 0]
    return 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])


def _p1_laplacian(points: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """Stiffness matrix of -Δ with linear triangles (cotangent weights)."""
    p = points[triangles]
    area = _signed_area_2d(p)
    # gradients of the barycentric functions: rot90 of the opposite edge / (2 A)
    grads = np.empty((len(triangles), 3, 2))
    for i in range(3):
        e = p[:, (i + 2) % 3] - p[:, (i + 1) % 3]
        grads[:, i] = np.stack([-e[:, 1], e[:, 0]], axis=1) / (2 * area[:, None])
    local = np.einsum("mik,mjk->mij", grads, grads) * area[:, None, None]
    rows = np.repeat(triangles, 3, axis=1).ravel()
    cols = np.tile(triangles, (1, 3)).ravel()
    n = len(points)
    return sp.csr_matrix((local.ravel(), (rows, cols)), shape=(n, n))


def _harmonic(points: np.ndarray, triangles: np.ndarray, fixed: np.ndarray,
              values: np.ndarray, source: float = 0.0) -> np.ndarray:
    """Solve -Δφ = source with φ = values on ``fixed`` nodes (natural BC elsewhere)."""
    n = len(points)
    K = _p1_laplacian(points, triangles)
    free = np.setdiff1d(np.arange(n), fixed)
    phi = np.zeros((n,) + values.shape[1:])
    phi[fixed] = values
    rhs = -K[free][:, fixed] @ values
    if source:
        area = np.abs(_signed_area_2d(points[triangles]))
        lumped = np.bincount(triangles.ravel(), np.repeat(area / 3, 3), minlength=n)
        rhs = rhs + (source * lumped[free]).reshape((-1,) + (1,) * (values.ndim - 1))
    phi[free] = spla.spsolve(K[free][:, free].tocsc(), rhs).reshape(phi[free].shape)
    return phi


def place_graft(graft: FlatLeafletMesh, native: LeafletShape, placement: str = "conformal",
                billow_mm: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Map the graft's flat points to native-leaflet flat coordinates, and an inward offset.

    The attachment edge is sewn onto the native attachment locus by normalised
    arc length, segment by segment (each commissure onto the native commissure,
    lower edge onto lower edge), which keeps the commissure corners at the
    commissures the neighbouring leaflets share.  Interior points follow the
    affine map ``(x/(1+W), y/(1+H))`` -- which takes the graft outline onto the
    native outline -- corrected by the harmonic extension of the attachment
    correction, so the placement is smooth and untangled.

    Returns
    -------
    native_flat
        ``(n, 2)`` points in the native leaflet's flat coordinates (to be wrapped).
    inward
        ``(n,)`` extra displacement towards the valve axis (mm): zero for
        ``"conformal"``, a smooth bulge of height ``billow_mm`` (negative: outwards)
        vanishing on the attachment for ``"billowed"``.
    """
    gs = graft.shape
    pts = graft.points
    affine = pts / np.array([gs.sx, gs.sy])
    target = affine.copy()
    # lower edge: equal normalised arc length
    xg, sg = gs.lower_edge_arclength()
    xn, sn = native.lower_edge_arclength()
    tau = np.interp(pts[graft.lower, 0], xg, sg) / sg[-1]
    x_native = np.interp(tau * sn[-1], sn, xn)
    target[graft.lower, 0] = x_native
    target[graft.lower, 1] = native.lower_edge(x_native)
    # commissures: uniform nodes onto the uniform native commissure nodes
    for chain, sign in ((graft.left, -1.0), (graft.right, 1.0)):
        t = np.linspace(0.0, 1.0, len(chain))
        target[chain, 0] = sign * native.half_width
        target[chain, 1] = native.commissure_bottom + t * native.commissure_height
    fixed = graft.attachment
    correction = _harmonic(pts, graft.triangles, fixed, target[fixed] - affine[fixed])
    native_flat = affine + correction
    native_flat[fixed] = target[fixed]
    inward = np.zeros(len(pts))
    if placement == "billowed" and billow_mm != 0:
        bump = _harmonic(pts, graft.triangles, fixed, np.zeros(len(fixed)), source=1.0)
        inward = billow_mm * bump / bump.max()
    elif placement not in GRAFT_PLACEMENTS:
        raise ParameterError(f"graft_placement = {placement!r}; choose one of {GRAFT_PLACEMENTS}")
    return native_flat, inward


def build_valve(params: ValveParameters | None = None, **overrides) -> ValveMesh:
    """Build the three-leaflet valve (normal, or with a graft) as a :class:`ValveMesh`.

    ``overrides`` are :class:`ValveParameters` fields, e.g.
    ``build_valve(mesh_size=0.5, graft_width_pct=21, graft_height_pct=27)``.
    """
    if params is None:
        params = ValveParameters(**overrides)
    elif overrides:
        params = ValveParameters(**{**params.to_dict(), **overrides})
    native_shape = params.native_shape()
    native = mesh_flat_leaflet(native_shape, params.mesh_size)
    flats: list[FlatLeafletMesh] = [native, native, native]
    if params.has_graft:
        flats[GRAFT_POSITION] = mesh_flat_leaflet(params.graft_shape(), params.mesh_size,
                                                  n_commissure=len(native.left))
    local_to_global, num_nodes = _shared_node_ids(flats)
    positions = [_wrapped_leaflet(fm, k, params, native_shape) for k, fm in enumerate(flats)]
    points = _joined_points(local_to_global, positions, num_nodes, params.root_diameter)

    cells, tags, flat_cells, fibres, patches = [], [], [], [], []
    edges, edge_tags = [], []
    for k, (fm, ids) in enumerate(zip(flats, local_to_global, strict=True)):
        is_graft = params.has_graft and k == GRAFT_POSITION
        tag = k + 1
        cells.append(ids[fm.triangles])
        tags.append(np.full(len(fm.triangles), tag, dtype=np.int32))
        flat_cells.append(fm.points[fm.triangles])
        fibres.append(_cell_fibres(fm, is_graft, params.graft_fibre_angle_deg))
        be = fm.boundary_edges()
        for key in ("lower", "left", "right"):
            edges.append(ids[be[key]])
            edge_tags.append(np.full(len(be[key]), ATTACHMENT, dtype=np.int32))
        edges.append(ids[be["free"]])
        edge_tags.append(np.full(len(be["free"]), FREE_EDGE, dtype=np.int32))
        patches.append(LeafletPatch(
            name=LEAFLET_NAMES[k], tag=tag, shape=fm.shape, nodes=ids, flat=fm.points,
            triangles=fm.triangles, free_edge=fm.free, attachment=fm.attachment,
            is_graft=is_graft))

    # commissure edges appear twice (once per leaflet): keep one
    all_edges = np.sort(np.concatenate(edges), axis=1)
    all_tags = np.concatenate(edge_tags)
    all_edges, first = np.unique(all_edges, axis=0, return_index=True)
    valve = ValveMesh(
        points=points,
        cells=np.concatenate(cells),
        cell_tags=np.concatenate(tags),
        flat=np.concatenate(flat_cells),
        fibres=np.concatenate(fibres),
        edges=all_edges,
        edge_tags=all_tags[first],
        leaflets=tuple(patches),
        parameters=params,
    )
    log.info("valve mesh: %d nodes, %d triangles%s", valve.num_nodes, valve.num_cells,
             f", graft {GraftSize(params.graft_width_pct, params.graft_height_pct).label}"
             if params.has_graft else "")
    return valve.validate()


def _shared_node_ids(flats: list[FlatLeafletMesh]) -> tuple[list[np.ndarray], int]:
    """Each leaflet's node ids in the valve, and their count: a leaflet's left commissure
    is the previous leaflet's right one, and the last leaflet's right commissure the first
    one's left."""
    local_to_global: list[np.ndarray] = []
    next_id = 0
    for k, fm in enumerate(flats):
        ids = np.full(len(fm.points), -1, dtype=np.int64)
        if k > 0:
            ids[fm.left] = local_to_global[k - 1][flats[k - 1].right]
        if k == len(flats) - 1:
            ids[fm.right] = local_to_global[0][flats[0].left]
        new = ids < 0
        ids[new] = np.arange(next_id, next_id + new.sum())
        next_id += int(new.sum())
        local_to_global.append(ids)
    return local_to_global, next_id


def _wrapped_leaflet(fm: FlatLeafletMesh, k: int, params: ValveParameters,
                     native_shape: LeafletShape) -> np.ndarray:
    """``(n, 3)`` positions of leaflet ``k``'s nodes on the root; a graft is placed on the
    native leaflet's attachment first (:func:`place_graft`)."""
    centre = 2.0 * math.pi * k / 3.0
    if not (params.has_graft and k == GRAFT_POSITION):
        return wrap_flat(fm.points, centre, params.root_diameter)
    native_flat, inward = place_graft(fm, native_shape, params.graft_placement,
                                      params.billow_mm)
    xyz = wrap_flat(native_flat, centre, params.root_diameter)
    radial = xyz[:, :2] / np.linalg.norm(xyz[:, :2], axis=1, keepdims=True)
    xyz[:, :2] -= inward[:, None] * radial
    return xyz


def _joined_points(local_to_global: list[np.ndarray], positions: list[np.ndarray],
                   num_nodes: int, diameter: float) -> np.ndarray:
    """The valve's ``(num_nodes, 3)`` node positions; a shared commissure node must sit
    where both its leaflets put it."""
    points = np.full((num_nodes, 3), np.nan)
    for k, (ids, xyz) in enumerate(zip(local_to_global, positions, strict=True)):
        shared = ~np.isnan(points[ids, 0])
        if np.any(shared):
            gap = np.abs(points[ids[shared]] - xyz[shared]).max()
            if gap > 1e-9 * diameter:
                raise MeshError(f"commissure nodes of leaflet {k} miss their neighbour's by "
                                f"{gap:.3g} mm; cannot join the leaflets")
        points[ids[~shared]] = xyz[~shared]
    return points


def _cell_fibres(fm: FlatLeafletMesh, is_graft: bool, graft_angle_deg: float) -> np.ndarray:
    """``(cells, 2)`` unit fibre directions in the flat chart: the native leaflet's
    circumferential field, or the graft's one direction."""
    if is_graft:
        a = math.radians(graft_angle_deg)
        return np.tile([math.cos(a), math.sin(a)], (len(fm.triangles), 1))
    centroids = fm.points[fm.triangles].mean(axis=1)
    return fm.shape.fibre_direction(centroids[:, 0], centroids[:, 1])
