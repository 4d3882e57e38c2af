"""Batch rigid-body dynamics over whole trials, wrapping Pinocchio.

Arrays are time-first, ``(N, nq)`` / ``(N, nv)``; Pinocchio is called in a
tight loop writing into preallocated output, with one ``pin.Data`` workspace
per call (or the one passed in), so the Python layer adds little to a bare
``pin.rnea`` loop (see ``benchmarks/``).

External forces cross the API as world-frame wrenches applied at a point on a
body (:class:`ExternalForce`): the world wrench at the world origin is
``(f, p x f + tau)``, and its generalized force ``J^T W`` is subtracted from a
bare RNEA (computed over all frames at once along the loaded body's supporting
joints, :func:`_loads_generalized_force`; the same numbers as Pinocchio's
joint-local ``fext``, ``oMi.actInv(W)``).
"""
from __future__ import annotations

import difflib
import threading
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from .errors import ModelError, SolverError


def _pin(model) -> pin.Model:
    return model.pin if hasattr(model, "pin") else model


_CONSTANTS: dict[tuple[int, str], tuple[pin.Model, object]] = {}


def skeleton_constant(pmodel: pin.Model, key: str, compute: Callable[[pin.Model], object]):
    """``compute(pmodel)``, kept per Pinocchio model object and ``key``: what analyses derive from the
    skeleton alone (frame names, joint column maps, is-planar) is computed once, not per call.  Keyed
    by the model object's identity (checked, so a recycled id recomputes); at most 256 entries kept.
    The answer must be immutable (a tuple, a frozen mapping): every caller shares it."""
    k = (id(pmodel), key)
    hit = _CONSTANTS.get(k)
    if hit is not None and hit[0] is pmodel:
        return hit[1]
    out = compute(pmodel)
    if len(_CONSTANTS) >= 256:
        _CONSTANTS.pop(next(iter(_CONSTANTS)))
    _CONSTANTS[k] = (pmodel, out)
    return out


def _frames(x: np.ndarray, n: int, what: str) -> np.ndarray:
    """``x`` as a C-contiguous float (N, n) array; a single (n,) row becomes (1, n)."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[None, :]
    if x.ndim != 2 or x.shape[1] != n:
        raise ModelError(f"{what} must have shape (N, {n}) (time-first); got {np.shape(x)}")
    return np.ascontiguousarray(x)


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of ``(N, 3)`` arrays, the same numbers as ``np.cross`` (its formula and
    operation order) without its axis handling, which costs ~10x the arithmetic on a trial's arrays."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


@dataclass(frozen=True)
class ExternalForce:
    """A world-frame force (and optional free torque) applied at a world point on a body.

    ``frame`` names a Pinocchio frame (or joint) of the body that receives the
    load; ``force``, ``point`` and ``torque`` are ``(N, 3)`` in N, m, N m.
    """

    frame: str
    force: np.ndarray
    point: np.ndarray
    torque: np.ndarray | None = None



def _frame_joint(pmodel: pin.Model, name: str) -> int:
    if pmodel.existFrame(name):
        return pmodel.frames[pmodel.getFrameId(name)].parentJoint
    if pmodel.existJointName(name):
        return pmodel.getJointId(name)
    names = [f.name for f in pmodel.frames]
    close = difflib.get_close_matches(name, names, n=3)
    hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
    raise ModelError(f"model has no frame or body '{name}'{hint}")


def world_wrench(ext: ExternalForce, n: int) -> np.ndarray:
    """(N, 6) spatial force ``[f, p x f + tau]`` of an :class:`ExternalForce` about the world origin."""
    f = _frames(ext.force, 3, f"external force on '{ext.frame}'")
    p = _frames(ext.point, 3, f"application point on '{ext.frame}'")
    if f.shape[0] != n or p.shape[0] != n:
        raise ModelError(
            f"external force on '{ext.frame}' has {f.shape[0]} frames and its point {p.shape[0]}; "
            f"the motion has {n}"
        )
    tq = None if ext.torque is None else _frames(ext.torque, 3, f"external torque on '{ext.frame}'")
    if tq is not None and tq.shape == f.shape and not p.any():
        m = tq          # wrenches about the origin already (prepare's GRF): 0 x f + tau is tau
    else:
        m = cross3(p, f)
        if tq is not None:
            m = m + tq
    return np.hstack([f, m])


#: Frames between two ``progress.update`` calls of the long loops here.
PROGRESS_CHUNK = 4096


_POOLS = threading.local()


def _massless(inertia: pin.Inertia) -> bool:
    return inertia.mass == 0.0 and not np.any(inertia.lever) and not np.any(inertia.inertia)


_XYZ = ["JointModelPX", "JointModelPY", "JointModelPZ"]


def compact_skeleton(pm: pin.Model) -> pin.Model:
    """The same multibody system with each chain of joints that carry no mass between them folded into one
    ``JointModelComposite``, for the batched RNEA.

    An OpenSim CustomJoint or a planar pelvis is a chain of one-dof joints with massless bodies between
    them (Rajagopal: 47 joints, 28 of them carrying nothing but the next joint).  RNEA costs about the
    same per joint whatever its body, so a composite of a chain (one body, one spatial-force pass, its
    sub-joints' motion composed inside) does the same work in fewer steps; sliders along x, y, z with
    nothing between them become one ``JointModelTranslation`` inside it.  Rajagopal's 47 joints become
    18, its RNEA ~20 % faster.

    A joint joins its parent's composite when the parent's body is massless (mass, lever and rotational
    inertia all zero), the joint is the parent's only child (nothing acts on, or hangs from, the
    intermediate frame) and it follows its parent in the joint order.  The chain's joints are then
    consecutive in ``q`` and ``v``, and a composite's configuration and velocity are its sub-joints' in
    order, so ``q``, ``v``, ``a`` and ``tau`` keep their layout (checked); armature and what is welded to
    the world are copied.  The result agrees with RNEA on ``pm`` to rounding (tests/test_skeleton.py).
    Returns ``pm`` itself when there is no chain to fold.
    """
    n = pm.njoints
    children = [[] for _ in range(n)]
    for j in range(1, n):
        children[pm.parents[j]].append(j)
    head = list(range(n))           # the first joint of each joint's chain
    for j in range(1, n):
        p = pm.parents[j]
        # j == p + 1: the chain's joints are consecutive, so their q and v columns are too
        if p > 0 and j == p + 1 and len(children[p]) == 1 and _massless(pm.inertias[p]):
            head[j] = head[p]
    if head == list(range(n)):
        return pm
    chains: dict[int, list[int]] = {}
    for j in range(1, n):
        chains.setdefault(head[j], []).append(j)
    m = pin.Model()
    m.name = pm.name
    m.gravity = pm.gravity
    new = {0: 0}
    for h in sorted(chains):
        chain = chains[h]
        if len(chain) == 1:
            jm = pm.joints[h]
        else:
            jm = pin.JointModelComposite()
            k = 0
            while k < len(chain):
                j = chain[k]
                placement = pin.SE3.Identity() if k == 0 else pm.jointPlacements[j]
                if [pm.joints[i].shortname() for i in chain[k:k + 3]] == _XYZ and all(
                        pm.jointPlacements[i].isIdentity() for i in chain[k + 1:k + 3]):
                    # sliders along x, y, z with nothing between them: one 3-dof translation joint, whose
                    # configuration and velocity are the three displacements in that order
                    jm.addJoint(pin.JointModelTranslation(), placement)
                    k += 3
                    continue
                jm.addJoint(pm.joints[j], placement)
                k += 1
        jid = m.addJoint(new[pm.parents[h]], jm, pm.jointPlacements[h], pm.names[chain[-1]])
        m.appendBodyToJoint(jid, pm.inertias[chain[-1]], pin.SE3.Identity())
        for j in chain:
            new[j] = jid
    if m.nq != pm.nq or m.nv != pm.nv or any(
            (m.joints[new[h]].idx_q, m.joints[new[h]].idx_v) != (pm.joints[h].idx_q, pm.joints[h].idx_v) for h in chains):
        raise ModelError(f"compact_skeleton of '{pm.name}': the folded skeleton's q/v layout differs")
    m.armature = pm.armature.copy()
    m.inertias[0] = pm.inertias[0]      # what is welded to the world (no dynamics, but the same model mass)
    return m


def _pool(model) -> pin.ModelPool | None:
    """A one-thread :class:`pinocchio.ModelPool` of a pinmsk model's skeleton, folded by
    :func:`compact_skeleton`, for ``pin.rneaInParallel`` (one C++ loop over a chunk of frames instead of
    one Python call a frame), kept per thread (its Data is a workspace) and per skeleton object (checked
    by identity; at most 8 kept).  None for a bare ``pin.Model``: that one is mutable, and a pool holds a
    copy."""
    if not hasattr(model, "pin"):
        return None
    pm = model.pin
    pools = getattr(_POOLS, "pools", None)
    if pools is None:
        pools = _POOLS.pools = {}
    hit = pools.get(id(pm))
    if hit is None or hit[0] is not pm:
        if len(pools) >= 8:
            pools.pop(next(iter(pools)))
        hit = pools[id(pm)] = (pm, pin.ModelPool(compact_skeleton(pm), 1))
    return hit[1]


def _rnea_frames(pm: pin.Model, pd: pin.Data, pool, q, v, a, out) -> None:
    """``out[i] = rnea(q[i], v[i], a[i])`` for the rows of (N, n) C-ordered arrays: through ``pool`` (their
    transposes are the column-major (n, N) blocks Pinocchio's batch call takes, no copy) or frame by frame."""
    if pool is not None and q.shape[0]:
        pin.rneaInParallel(1, pool, q.T, v.T, a.T, out.T)
        return
    rnea = pin.rnea
    for i in range(q.shape[0]):
        out[i] = rnea(pm, pd, q[i], v[i], a[i])


def rnea(model, q, v, a, *, external: Sequence[ExternalForce] = (),
                     data: pin.Data | None = None, progress=None) -> np.ndarray:
    """Joint generalized forces ``tau = M(q) a + h(q, v) - J^T f_ext`` over frames (RNEA).

    Returns ``(N, nv)``.  ``external`` lists world-frame wrenches at points.
    ``progress``: an object with ``update(n)``, called every
    :data:`PROGRESS_CHUNK` frames (e.g. :class:`pinmsk.presentation.progress.Progress`).
    On a pinmsk model the frames go through Pinocchio's batch ``rneaInParallel`` on one thread
    (:func:`_pool`; ``data`` is then not used); on a bare ``pin.Model``, one ``pin.rnea`` call a frame.
    """
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    v = _frames(v, pm.nv, "v")
    a = _frames(a, pm.nv, "a")
    n = q.shape[0]
    if v.shape[0] != n or a.shape[0] != n:
        raise ModelError(f"q, v, a have {n}, {v.shape[0]}, {a.shape[0]} frames; they must match")
    out = np.empty((n, pm.nv))
    pool = _pool(model)
    # a Data costs milliseconds on a large skeleton: made only where a per-frame call needs one
    pd = data if data is not None or pool is not None else pm.createData()
    rnea = pin.rnea
    if not external:
        for start in range(0, n, PROGRESS_CHUNK):
            stop = min(start + PROGRESS_CHUNK, n)
            _rnea_frames(pm, pd, pool, q[start:stop], v[start:stop], a[start:stop], out[start:stop])
            if progress is not None:
                progress.update(stop - start)
        return out
    joints = [skeleton_constant(pm, "frame_joint:" + e.frame, lambda m, f=e.frame: _frame_joint(m, f))
              for e in external]
    wrenches = [world_wrench(e, n) for e in external]
    loaded = tuple(sorted(set(joints)))
    W = {j: sum(w for jj, w in zip(joints, wrenches) if jj == j) for j in loaded}
    Wall = np.stack([W[j] for j in loaded])
    tree = skeleton_constant(pm, f"support_tree:{loaded}", lambda m: _support_tree(m, loaded))
    if tree is not None:
        # tau = rnea(q, v, a) - sum_j J_j(q)^T W_j (rnea is linear in the loads), the loads' part carried
        # down their support tree in numpy over a chunk of frames at once: ONE Pinocchio call a frame
        # (the bare RNEA loop), no per-frame Jacobian, Force or pose
        for start in range(0, n, PROGRESS_CHUNK):
            stop = min(start + PROGRESS_CHUNK, n)
            _rnea_frames(pm, pd, pool, q[start:stop], v[start:stop], a[start:stop], out[start:stop])
            out[start:stop] -= _loads_generalized_force(tree, q[start:stop], pm.nv, Wall[:, start:stop])
            if progress is not None:
                progress.update(stop - start)
        return out
    # tau = rnea(q, v, a) - sum_j J_j(q)^T W_j, with W_j the world wrench about the origin and J_j the
    # joint's Jacobian in the world frame (WORLD: the motion subspaces of its supporting joints, at the
    # origin, as computeJointJacobians leaves them in data.J): two Pinocchio calls a frame, the products
    # batched over frames, for the joint types :func:`_support_tree` does not carry loads across
    pd = pm.createData() if pd is None else pd
    cols = {j: skeleton_constant(pm, f"support_columns:{j}", lambda m, j=j: _support_columns(m, j)) for j in loaded}
    # the whole data.J copied per frame (one contiguous copy, cheaper than a fancy-indexed column pick),
    # a chunk of frames at a time so long trials keep a bounded workspace
    J = np.empty((min(n, PROGRESS_CHUNK), 6, pm.nv))
    # eigenpy hands a 6 x 1 matrix back as a vector (a one-dof model): fill J through a (6,) view then
    Jw = J if pm.nv > 1 else J[:, :, 0]
    jac = pin.computeJointJacobians
    for start in range(0, n, PROGRESS_CHUNK):
        stop = min(start + PROGRESS_CHUNK, n)
        for k, (qi, vi, ai) in enumerate(zip(q[start:stop], v[start:stop], a[start:stop])):
            out[start + k] = rnea(pm, pd, qi, vi, ai)
            Jw[k] = jac(pm, pd, qi)
        m = stop - start
        for j in loaded:
            out[start:stop, cols[j]] -= np.einsum("nrc,nr->nc", J[:m][:, :, cols[j]], W[j][start:stop])
        if progress is not None:
            progress.update(m)
    return out


#: Pinocchio joints :func:`_support_tree` carries loads across: one dof about (revolute) or along (prismatic) a
#: constant axis of the joint frame, ``q`` the angle or the displacement.
_AXES = {"JointModelRX": (True, (1.0, 0.0, 0.0)), "JointModelRY": (True, (0.0, 1.0, 0.0)),
         "JointModelRZ": (True, (0.0, 0.0, 1.0)), "JointModelPX": (False, (1.0, 0.0, 0.0)),
         "JointModelPY": (False, (0.0, 1.0, 0.0)), "JointModelPZ": (False, (0.0, 0.0, 1.0)),
         "JointModelRevoluteUnaligned": (True, None), "JointModelPrismaticUnaligned": (False, None)}


#: The unit axes along x, y, z and their index.
_AXIS_INDEX = {(1.0, 0.0, 0.0): 0, (0.0, 1.0, 0.0): 1, (0.0, 0.0, 1.0): 2}


@dataclass(frozen=True)
class _ChainJoint:
    """One joint of the loaded joints' support tree, as carrying the loads' wrenches to it needs.  A
    wrench is a column ``x = [f; m]`` (force, moment about the frame's origin) in the joint's placement
    frame; ``S`` is the joint's motion subspace, so ``S . x`` is the joint's generalized force (the
    axial moment of a revolute joint, which its rotation leaves as it is; the axial force of a
    prismatic one): row ``S_row`` of ``x`` times ``S_sign`` for an axis along +-x, y or z.  The
    parent's ``x`` is carried through the parent's own motion (``parent_axis``, ``parent_iq`` the column
    of its angle or displacement, ``parent_k``/``parent_sign`` its axis as ``+-e_k``; revolute: Rodrigues'
    rotation by ``-q`` of both halves, prismatic: the moment about the moved origin ``m - q a x f``) and
    then this joint's placement ``X`` (None: the identity, which a chain of an OpenSim CustomJoint's axes
    mostly has).  ``pick`` selects this joint's loads among its parent's (None: all of them)."""

    parent: int
    parent_revolute: bool
    parent_axis: np.ndarray | None      # None: the world parent
    parent_iq: int
    parent_k: int                       # the parent's axis is parent_sign e_k (-1: another axis, or the world)
    parent_sign: float
    joint: int
    iv: int
    X: np.ndarray | None
    S: np.ndarray
    S_row: int                          # -1: not along a frame axis (use S)
    S_sign: float
    pick: tuple[int, ...] | None


def _placement_rows(M: pin.SE3) -> np.ndarray:
    """The 6 x 6 ``X`` with ``X x`` the wrench column ``x`` (about the parent's origin, in its axes)
    about the placement's origin in its axes: ``[Rp^T f; Rp^T (m - p x f)]``."""
    R, p = np.array(M.rotation), np.array(M.translation)
    P = np.array([[0.0, -p[2], p[1]], [p[2], 0.0, -p[0]], [-p[1], p[0], 0.0]])
    X = np.zeros((6, 6))
    X[:3, :3] = X[3:, 3:] = R.T
    X[3:, :3] = -R.T @ P
    return X


def _support_tree(pm: pin.Model, loaded: tuple[int, ...]) -> tuple[_ChainJoint, ...] | None:
    """The joints supporting the ``loaded`` joints, parents first, or None when one is a joint
    :data:`_AXES` lacks (the caller then takes Pinocchio's Jacobians)."""
    members = sorted({s for j in loaded for s in pm.supports[j][1:]})
    kinds = {}
    for s in members:
        jm = pm.joints[s]
        kind = _AXES.get(jm.shortname())
        if kind is None or jm.nq != 1 or jm.nv != 1:
            return None
        a = np.array(jm.extract().axis if kind[1] is None else kind[1], dtype=float)
        if abs(a @ a - 1.0) > 1e-12:        # Pinocchio takes the axis as given: Rodrigues needs it unit
            return None
        a.flags.writeable = False
        kinds[s] = (kind[0], a, jm.idx_q, jm.idx_v)
    loads = {s: tuple(i for i, j in enumerate(loaded) if s in pm.supports[j]) for s in members}
    loads[0] = tuple(range(len(loaded)))
    out = []
    for s in members:
        parent = pm.parents[s]
        X = _placement_rows(pm.jointPlacements[s])
        if np.array_equal(X, np.eye(6)):
            X = None
        else:
            X.flags.writeable = False
        revolute, a, iq, _ = kinds[parent] if parent else (False, None, 0, 0)
        own = kinds[s]
        S = np.concatenate([np.zeros(3), own[1]] if own[0] else [own[1], np.zeros(3)])
        S.flags.writeable = False
        hit = np.flatnonzero(S)
        S_row = int(hit[0]) if hit.size == 1 and abs(S[hit[0]]) == 1.0 else -1
        pick = None if loads[s] == loads[parent] else tuple(loads[parent].index(i) for i in loads[s])
        k, sign = _signed_axis(a)
        out.append(_ChainJoint(parent, revolute, a, iq, k, sign, s, own[3], X, S, S_row,
                               float(S[S_row]) if S_row >= 0 else 1.0, pick))
    return tuple(out)


def _signed_axis(a: np.ndarray | None) -> tuple[int, float]:
    """``(k, sign)`` with ``a = sign e_k`` (a left leg's OpenSim axes are often -x, -y), or ``(-1, 1.0)``."""
    if a is None:
        return -1, 1.0
    k = _AXIS_INDEX.get(tuple(a.tolist()), -1)
    if k >= 0:
        return k, 1.0
    k = _AXIS_INDEX.get(tuple((-a).tolist()), -1)
    return k, (-1.0 if k >= 0 else 1.0)


def _axis_cross(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``a x x`` for a constant axis ``a`` (3,) and rows ``x`` (3, ...), skipping the axis' zero entries."""
    out = np.zeros_like(x)
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):      # (a x x)_i = a_j x_k - a_k x_j
        if a[j]:
            out[i] += a[j] * x[k]
        if a[k]:
            out[i] -= a[k] * x[j]
    return out


def _loads_generalized_force(tree: tuple[_ChainJoint, ...], q: np.ndarray, nv: int,
                             W: np.ndarray) -> np.ndarray:
    """``sum_j J_j(q)^T W_j`` over frames, ``(N, nv)``, for world wrenches ``W`` ``(L, N, 6)`` about the
    origin on the loaded joints of :func:`_support_tree` ``tree``.  The wrenches are carried down the
    tree from the world, expressed in each joint's frame in turn (``oMs^-1 W``), and each joint's
    column is its motion subspace times the wrenches it carries, ``S^T oMs^-1 W``: the world Jacobian's
    column times ``W``, a few (6, L N) array operations a joint instead of a Pinocchio call a frame."""
    n = q.shape[0]
    out = np.empty((nv, n)) if nv else np.zeros((0, n))
    out[:] = 0.0
    x = {0: np.ascontiguousarray(W.transpose(2, 0, 1))}     # (6, L, N): wrench rows first
    # the revolute parents' cos and sin, every angle in one call each (rows: contiguous per joint)
    iq = sorted({c.parent_iq for c in tree if c.parent_axis is not None and c.parent_revolute})
    ang = np.ascontiguousarray(q[:, iq].T)
    cos_all, sin_all = np.cos(ang), np.sin(ang)
    row_of = {k: r for r, k in enumerate(iq)}
    for c in tree:
        xp = x[c.parent]
        if c.pick is not None:
            xp = xp[:, c.pick, :]
        if c.parent_axis is None:
            y = xp
        elif c.parent_revolute:
            # R(-q) x = cos q x - sin q (a x x) + (1 - cos q)(a . x) a on both halves
            r = row_of[c.parent_iq]
            cs, sn = cos_all[r], sin_all[r]
            a = c.parent_axis
            k = c.parent_k
            if k >= 0:                  # about +-e_k: a plane rotation of the other two rows of both halves
                i, j = (k + 1) % 3, (k + 2) % 3
                y = np.empty_like(xp)
                h, yh = xp.reshape(2, 3, *xp.shape[1:]), y.reshape(2, 3, *xp.shape[1:])
                yh[:, k] = h[:, k]
                ui, uj = h[:, i], h[:, j]
                if c.parent_sign > 0:
                    yh[:, i] = cs * ui + sn * uj
                    yh[:, j] = cs * uj - sn * ui
                else:                   # about -e_k: the rotation by +q about e_k
                    yh[:, i] = cs * ui - sn * uj
                    yh[:, j] = cs * uj + sn * ui
            else:
                y = np.empty_like(xp)
            cs1 = 1.0 - cs if k < 0 else None
            for h in (slice(0, 3), slice(3, 6)) if k < 0 else ():
                u = xp[h]
                r = cs * u
                r -= sn * _axis_cross(a, u)
                ax = sum(a[i] * u[i] for i in range(3) if a[i])
                r += (cs1 * ax) * a[:, None, None]
                y[h] = r
        else:
            y = xp.copy()               # m - q a x f, about the origin moved along the axis
            d = q[:, c.parent_iq]
            if c.parent_k >= 0:         # along e_k: (e_k x f)_i = -f_j and (e_k x f)_j = f_i, the rest 0
                i, j = (c.parent_k + 1) % 3, (c.parent_k + 2) % 3
                if c.parent_sign < 0:
                    i, j = j, i         # along -e_k: the opposite signs
                y[3 + i] += d * xp[j]
                y[3 + j] -= d * xp[i]
            else:
                y[3:] -= d * _axis_cross(c.parent_axis, xp[:3])
        if c.X is None:
            xc = y
        else:
            L = y.shape[1]
            xc = (c.X @ y.reshape(6, L * n)).reshape(6, L, n)
        x[c.joint] = xc
        if c.S_row >= 0:
            out[c.iv] = xc[c.S_row, 0] if xc.shape[1] == 1 else xc[c.S_row].sum(axis=0)
            if c.S_sign < 0:
                out[c.iv] *= -1.0
        else:
            L = xc.shape[1]
            out[c.iv] = (c.S @ xc.reshape(6, L * n)).reshape(L, n).sum(axis=0)
    return out.T


def _support_columns(pm: pin.Model, j: int) -> np.ndarray:
    """The velocity columns of the joints supporting joint ``j`` (its world Jacobian's nonzero columns)."""
    cols = np.array([pm.joints[s].idx_v + k for s in pm.supports[j][1:] for k in range(pm.joints[s].nv)],
                    dtype=np.intp)
    cols.flags.writeable = False
    return cols


def external_generalized_force(model, q, external: Sequence[ExternalForce]) -> np.ndarray:
    """``J^T f_ext`` over frames, ``(N, nv)``: the generalized force of external wrenches."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    z = np.zeros((q.shape[0], pm.nv))
    return rnea(pm, q, z, z, external=()) - rnea(pm, q, z, z, external=external)


def forward_dynamics(model, q, v, tau, *, data: pin.Data | None = None) -> np.ndarray:
    """Accelerations ``a = M^-1 (tau - h)`` over frames (ABA); returns ``(N, nv)``."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    v = _frames(v, pm.nv, "v")
    tau = _frames(tau, pm.nv, "tau")
    pd = data if data is not None else pm.createData()
    out = np.empty((q.shape[0], pm.nv))
    aba = pin.aba
    for i in range(q.shape[0]):
        out[i] = aba(pm, pd, q[i], v[i], tau[i])
    return out


def mass_matrix(model, q, *, data: pin.Data | None = None) -> np.ndarray:
    """Joint-space inertia ``M(q)`` over frames, ``(N, nv, nv)``, symmetric (CRBA)."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    pd = data if data is not None else pm.createData()
    out = np.empty((q.shape[0], pm.nv, pm.nv))
    for i in range(q.shape[0]):
        M = pin.crba(pm, pd, q[i])
        out[i] = np.triu(M) + np.triu(M, 1).T
    return out


def gravity_torque(model, q, *, data: pin.Data | None = None) -> np.ndarray:
    """Generalized gravity ``g(q)`` over frames (the torque that holds the pose), ``(N, nv)``."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    pd = data if data is not None else pm.createData()
    out = np.empty((q.shape[0], pm.nv))
    for i in range(q.shape[0]):
        out[i] = pin.computeGeneralizedGravity(pm, pd, q[i])
    return out


def nonlinear_effects(model, q, v, *, data: pin.Data | None = None) -> np.ndarray:
    """Coriolis, centrifugal and gravity terms ``h(q, v)`` over frames, ``(N, nv)``."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    v = _frames(v, pm.nv, "v")
    pd = data if data is not None else pm.createData()
    out = np.empty((q.shape[0], pm.nv))
    for i in range(q.shape[0]):
        out[i] = pin.nonLinearEffects(pm, pd, q[i], v[i])
    return out


def _derivatives(fn, model, q, v, x, x_name, data):
    """Run a Pinocchio derivative routine over frames; the third output is symmetrised."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    v = _frames(v, pm.nv, "v")
    x = _frames(x, pm.nv, x_name)
    pd = data if data is not None else pm.createData()
    n = q.shape[0]
    d1 = np.empty((n, pm.nv, pm.nv))
    d2 = np.empty_like(d1)
    d3 = np.empty_like(d1)
    for i in range(n):
        r = fn(pm, pd, q[i], v[i], x[i])
        d1[i], d2[i] = r[0], r[1]
        # Pinocchio fills only the upper triangle of M / M^-1
        d3[i] = np.triu(r[2]) + np.triu(r[2], 1).T
    return d1, d2, d3


def rnea_derivatives(model, q, v, a, *, data: pin.Data | None = None):
    """``(dtau/dq, dtau/dv, M)`` over frames, each ``(N, nv, nv)`` (Pinocchio RNEA derivatives)."""
    return _derivatives(pin.computeRNEADerivatives, model, q, v, a, "a", data)


def aba_derivatives(model, q, v, tau, *, data: pin.Data | None = None):
    """``(da/dq, da/dv, da/dtau = M^-1)`` over frames, each ``(N, nv, nv)`` (Pinocchio ABA derivatives)."""
    return _derivatives(pin.computeABADerivatives, model, q, v, tau, "tau", data)


def mechanical_energy(model, q, v, *, data: pin.Data | None = None) -> np.ndarray:
    """Kinetic + potential energy over frames, ``(N,)`` in J (potential relative to the origin)."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    v = _frames(v, pm.nv, "v")
    pd = data if data is not None else pm.createData()
    out = np.empty(q.shape[0])
    for i in range(q.shape[0]):
        out[i] = pin.computeKineticEnergy(pm, pd, q[i], v[i]) + pin.computePotentialEnergy(pm, pd, q[i])
    return out


# -- forward simulation ---------------------------------------------------

#: ``tau_fn(t, q, v) -> (nv,)``: generalized force applied at time t and state (q, v).
TorqueFn = Callable[[float, np.ndarray, np.ndarray], np.ndarray]


def integrate(model, q0, v0, t, tau_fn: TorqueFn | None = None, *, method: str = "rk4",
              rtol: float = 1e-8, atol: float = 1e-10, data: pin.Data | None = None,
              progress=None):
    """Integrate ``M a + h = tau_fn(t, q, v)`` from ``(q0, v0)`` and return ``(q, v, a)`` at ``t``.

    ``method="rk4"`` takes fixed classical Runge-Kutta steps between the
    samples of ``t``; any other value (``"RK45"``, ``"DOP853"``, ``"Radau"``, ...)
    is passed to :func:`scipy.integrate.solve_ivp` with ``t_eval=t``.
    Requires ``nq == nv`` (models of 1-dof joints).
    """
    pm = _pin(model)
    if pm.nq != pm.nv:
        raise ModelError("integrate: models with multi-dof joints (nq != nv) are not supported yet")
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0):
        raise ModelError("integrate: t must be a strictly increasing 1-D array of at least 2 times")
    nv = pm.nv
    pd = data if data is not None else pm.createData()
    zero = np.zeros(nv)
    aba = pin.aba

    def accel(ti, q, v):
        tau = zero if tau_fn is None else np.asarray(tau_fn(ti, q, v), dtype=float)
        return aba(pm, pd, q, v, tau)

    n = t.size
    Q = np.empty((n, nv))
    V = np.empty((n, nv))
    A = np.empty((n, nv))
    q = np.array(q0, dtype=float).reshape(nv)
    v = np.array(v0, dtype=float).reshape(nv)
    if method.lower() == "rk4":
        Q[0], V[0] = q, v
        for i in range(n - 1):
            h = t[i + 1] - t[i]
            ti = t[i]
            k1q, k1v = v, accel(ti, q, v)
            A[i] = k1v
            k2q, k2v = v + 0.5 * h * k1v, accel(ti + 0.5 * h, q + 0.5 * h * k1q, v + 0.5 * h * k1v)
            k3q, k3v = v + 0.5 * h * k2v, accel(ti + 0.5 * h, q + 0.5 * h * k2q, v + 0.5 * h * k2v)
            k4q, k4v = v + h * k3v, accel(ti + h, q + h * k3q, v + h * k3v)
            q = q + h / 6.0 * (k1q + 2 * k2q + 2 * k3q + k4q)
            v = v + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
                raise SolverError(f"integrate: the state became non-finite at t = {t[i + 1]:.6g} s "
                                  f"(step {i + 1}); reduce the step or check the applied forces")
            Q[i + 1], V[i + 1] = q, v
            if progress is not None:
                progress.update(1)
        A[-1] = accel(t[-1], q, v)
        return Q, V, A
    from scipy.integrate import solve_ivp

    def rhs(ti, x):
        return np.concatenate([x[nv:], accel(ti, x[:nv], x[nv:])])

    sol = solve_ivp(rhs, (t[0], t[-1]), np.concatenate([q, v]), method=method, t_eval=t,
                    rtol=rtol, atol=atol)
    if not sol.success:
        raise SolverError(f"integrate: solve_ivp ({method}) failed at t = {sol.t[-1]:.6g} s: {sol.message}")
    Q[:] = sol.y[:nv].T
    V[:] = sol.y[nv:].T
    for i in range(n):
        A[i] = accel(t[i], Q[i], V[i])
    return Q, V, A
