"""The pair mechanism: a method's per-pair physics, written once, run over any neighbour set.

A method writes its pair physics as one small, pure numba function (PySPH's
``Equation.loop``, JAX-MD's ``smap.pair``) that *returns* the terms it adds::

    @numba.njit(cache=True, inline="always")
    def soft_sphere(a, b, r2, d, k, radius_s, v_sc):
        # k: a global parameter; radius_s, v_sc: per-point inputs, indexed by sorted extended point
        ...
        return (e_half, fx, fy, fz), (e_half, -fx, -fy, -fz), ()   # to a, to b, global

    SOFT = PairInteraction(soft_sphere, dict(energies=Output(()), forces=Output((3,))),
                           params=("k",), inputs=("radius_s", "v_sc"))
    out = SOFT.compute(nlist, r_pc, params=dict(k=2.0), inputs=dict(radius_s=radius_p, v_sc=v_pc))

Arguments: ``a`` and ``b`` are sorted extended points (particles and their periodic
ghosts, see :mod:`ase_sphrelax.neighbors`), ``d`` the tuple ``x_b - x_a`` of length D
(the dimension of the stored coordinates: 3 for ASE Atoms) and ``r2 = |d|^2``.
The data after ``(a, b, r2, d)`` are named in the signature: each name is declared
either a global parameter (``params``: numbers, small arrays, the same for every pair), a
per-particle input (``inputs``: arrays gathered to the extended points, read as ``v_s[a]``)
or a constant of the specialisation (``constants``: compiled in, so that a branch on a bool
constant is pruned and each value gives the flat form). The declaration is checked against
the signature at construction and the data at each :meth:`PairInteraction.compute`, by name.

Kernel placeholders: a pair function that calls ``kernel_profile(q)`` (-> ``f, f'``) or
``kernel_derivatives(q)`` (-> ``f, f', f'', f''', f''''``) of :mod:`ase_sphrelax.kernels` is
re-compiled per kernel (``compute(..., kernel=k)``) with those names bound to the kernel's
generated closed forms: no pair function branches on the kernel. The placeholders must be
called by the pair function itself (a helper of its own is another function, not re-compiled).
The terms are the per-point outputs flattened in their declared order (a scalar output
takes one term, a ``(3,)`` output three), and the global outputs (e.g. a virial) flattened
the same way. :class:`PairInteraction` turns the function into the loops:

* the walk over a stored Verlet half list, the bin scan fused with the pair physics
  (one-shot evaluations, no list stored), and the rebuild scan, which writes the Verlet
  list of a pending build (:attr:`NeighborList.build_pending`) and evaluates the pairs in
  the same pass, so that a rebuild costs one bin scan and no list walk (a point's candidates
  appended without a branch, then its listed pairs computed as the walk computes them; for a
  set of originals of one cut-off, :attr:`NeighborList.plain`, by the distance alone, two points
  of one bin scanning their rows together); all from one definition;
* a's terms summed in registers over its partners and written once; b's added to b;
  global terms summed per thread;
* serial below :data:`~ase_sphrelax.neighbors.PARALLEL_MIN` points, numba threads above it,
  each thread on a static chunk of points with its own output buffers (kept between calls:
  fresh pages cost more than the pair loop on these machines; zeroed by the thread itself;
  starting at the lowest point the chunk's pairs reach when the neighbours are ``forward_pairs``
  (``partner_starts``: the chunk's first point, lower for points of wide reach), and ending
  at the last point its pairs reach when they say so, ``partner_ends``), folded afterwards
  onto the particles, ghosts included.

Two kinds of interaction:

``symmetric=True``
    Called once per pair; returns ``(terms_a, terms_b, terms_global)`` (a pair potential,
    ``sum_b grad W_ab``, a symmetric pressure force).
``symmetric=False`` (gather)
    Written for "a gathers from b" (e.g. a density sum with a's own smoothing length
    ``H_a``); returns ``(terms_a, terms_global)`` and is called for both orientations,
    ``(a, b, d)`` and ``(b, a, -d)``.

Every pair within ``reach`` is passed to the function: with per-particle ranges (adaptive
``H``) it makes its own finer test and returns zeros beyond. Multi-pass evaluations (a
density pass, a per-particle update in numpy, then a force pass) are successive
:meth:`PairInteraction.compute` calls over the same neighbour list; per-point inputs are
gathered for the ghosts without image shifts
(:meth:`~ase_sphrelax.neighbors.NeighborList.gather`), positions with them
(:meth:`~ase_sphrelax.neighbors.NeighborList.extend`).

The loops are generated as Python source and compiled by numba against the physics
function's own source file, so that numba's disk cache holds them like any other jitted
function (numba functions that receive a jitted function as an argument, or capture one in
a closure, are recompiled in every process). A specialised pair function (its constants and
kernel bound as globals) is re-compiled from its source against the same file, under a name
that carries the kernel and a hash of the bound values, so that cache files never collide.
"""
from __future__ import annotations

import hashlib
import inspect
import itertools
from collections.abc import Mapping
from dataclasses import dataclass

import numba
import numpy as np

from .kernels import KERNEL_FUNCTIONS
from .neighbors import SCAN_HELPERS, SCAN_SOURCE, check_fold_output, release_free_memory, release_pages
from .parallel import chunk_bounds, run_chunks, thread_count
from .specialise import recompiled

__all__ = ["PairInteraction", "Output", "PairResult"]


@dataclass(frozen=True)
class Output:
    """An accumulator of a pair interaction.

    Parameters
    ----------
    shape : tuple of int
        Per-point shape: ``()`` for a scalar per point, ``(3,)`` for a vector.
    per_point : bool
        False for a global sum (e.g. the virial, shape ``(6,)``).
    spatial : bool
        True for a per-point vector of shape ``(3,)`` whose components are x, y, z of a spatial vector that
        vanishes along z when every point and every ``d`` lies in the plane z = 0 (a force ``g d``, a kernel
        gradient). A planar loop (:meth:`PairInteraction.compute` with ``planar=True``) does not accumulate its
        z component, which stays zero.
    """

    shape: tuple = ()
    per_point: bool = True
    spatial: bool = False

    @property
    def size(self):
        return int(np.prod(self.shape, dtype=int))


class PairResult(dict):
    """Outputs of :meth:`PairInteraction.compute` by name, per particle (or global)."""

    def __getattr__(self, name):
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None


# -- generated loops -------------------------------------------------------------------------
# Templates, filled with the unrolled term bookkeeping of one interaction; the walk itself
# is shared by all interactions.

_LIST_TEMPLATE = """
def {name}(x_sc, pair_start, pair_j, reach2, params, inp, out, base, first, last):
    {views}
    {zero_buffers}
    {zero_global}
    {scratch}
    for a in range(first, last):
        {load_a}
        {zero_own}
        begin = pair_start[a]
        stop = pair_start[a + 1]
        {terms}
        {store_own}
    {store_global}
"""

_SCAN_TEMPLATE = """
def {name}(x_sc, src_s, img_sc, is_ghost_s, bin_s, nbin_c, bin_start, stencil, reach2, params, inp, out,
           base, first, last):
    {views}
    {zero_buffers}
    {zero_global}
    for a in range(first, last):
        {load_a}
        {zero_own}
        kx, ky, kz = bin_coords(a, bin_s, nbin_c)
        for k in range(-1, stencil_rows(a, kx, ky, kz, nbin_c, stencil)):
            lo, hi = stencil_range(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil)
            for b in range(lo, hi):
                {diff}
                r2 = {norm2}
                if r2 >= reach2 or not is_canonical_pair(a, b, src_s, img_sc, is_ghost_s) \
                        or not finds_pair(a, b, stencil):
                    continue
                {body}
        {store_own}
    {store_global}
"""


# The fused builds: the same head, and the listed pairs' terms computed as the walk computes them
_BUILD_HEAD = """
def {name}(x_sc, src_s, img_sc, is_ghost_s, cut_s, skin, bin_s, nbin_c, bin_start, stencil, room, count_s, pair_j,
           pos, reach2, params, inp, out, base, first, last):
    {views}
    if pos == 0:  # the chunk's first call (a call resumed after growing pair_j has pos > 0)
        {zero_buffers_nested}
    {zero_global}
    {scratch}
    cap = pair_j.shape[0]
"""


_BUILD_TEMPLATE = _BUILD_HEAD + """    for a in range(first, last):
        # room for every candidate of a (at most ``room``), or stop before a (nothing of a is added yet)
        if pos + point_room(a, room, stencil) > cap:
            {store_global_early}
            return a, pos
        kx, ky, kz = bin_coords(a, bin_s, nbin_c)
        {load_a}
        {zero_own}
        ca = cut_s[a]
        start = pos
        # a's partners within max(cut-offs) + skin, appended without a branch on the test (each candidate is
        # written, and kept by moving on): whether a candidate is in reach is not predictable
        for k in range(-1, stencil_rows(a, kx, ky, kz, nbin_c, stencil)):
            lo, hi = stencil_range(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil)
            for b in range(lo, hi):
                {scan_diff}
                rc = max(ca, cut_s[b]) + skin
                pair_j[pos] = b
                # in reach, the canonical orientation of an original-ghost pair, found once by a wide point's stencil
                pos += ({norm_first} < rc * rc) & is_canonical_pair(a, b, src_s, img_sc, is_ghost_s) \\
                    & finds_pair(a, b, stencil)
        count_s[a + 1] = pos - start
        # then their terms, as a walk of the stored list computes them: the same pairs in the same order
        begin, stop = start, pos
        {terms}
        {store_own}
    {store_global}
    return last, pos
"""


# a plain build's bins hold no wide points: its stencil is the half stencil's array, read by _half_range itself.
# The points of one bin share their stencil rows: the rows' candidates are gathered once per bin into a flat list with
# their coordinates (contiguous, by coordinate), and each point of the bin takes its squared distances to them in one
# vector pass, then keeps those in reach (on Fan's sphere at 1e6, a build's scan and terms on each of two threads took
# 245-260 ms against 290-296 ms when two points of a bin scanned the rows together: the same list, in the same order)
_BUILD_PLAIN_TEMPLATE = _BUILD_HEAD + """    flat = np.empty(max(room, 1), dtype=pair_j.dtype)  # the candidates of a bin's stencil rows
    flat_x = np.empty(({read}, max(room, 1)))  # their coordinates
    flat_r2 = np.empty(max(room, 1))  # their squared distances to one point of the bin
    a0 = first
    while a0 < last:
        own_end = bin_start[bin_s[a0] + 1]
        bin_end = min(own_end, last)
        # room for every candidate of the bin's points (at most ``room`` each), or stop before a0
        if pos + (bin_end - a0) * room > cap:
            {store_global_early}
            return a0, pos
        kx, ky, kz = bin_coords(a0, bin_s, nbin_c)
        rc2 = (cut_s[a0] + skin) * (cut_s[a0] + skin)
        nc = 0
        for k in range(stencil.shape[0]):
            lo, hi = _half_range(a0, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil)
            for b in range(lo, hi):
                flat[nc] = b
                {flat_store}
                nc += 1
        for a in range(a0, bin_end):
            {load_point}
            start = pos
            # partners within the cut-off + skin, appended without a branch on the test (each candidate is written,
            # and kept by moving on): first the own bin's points after a, then the rows' (as the rows are scanned)
            for b in range(a + 1, own_end):
                {diff_first}
                pair_j[pos] = b
                pos += {norm_first} < rc2
            for q in range(nc):
                {flat_diff}
                flat_r2[q] = {norm_first}
            for q in range(nc):
                pair_j[pos] = flat[q]
                pos += flat_r2[q] < rc2
            count_s[a + 1] = pos - start
            # then its terms, as a walk of the stored list computes them: the same pairs in the same order
            begin, stop = start, pos
            {load_a}
            {zero_own}
            {terms}
            {store_own}
        a0 = bin_end
    {store_global}
    return last, pos
"""


def _targets(outputs, per_point, point, planar=False):
    """Buffer element of every flattened term of the per-point (or global) outputs:
    "o0[b - base]", "o1[b - base, 2]", "o2[5]", ... with ``o{k}`` this thread's buffer of
    output k, whose row 0 is point ``base`` (see :meth:`PairInteraction._thread_buffers`);
    None for the z component of a spatial output in a ``planar`` loop (not accumulated)."""
    names = []
    for k, output in enumerate(outputs):
        if output.per_point != per_point:
            continue
        for index in itertools.product(*[range(n) for n in output.shape]):
            if planar and output.spatial and index == (2,):
                names.append(None)
                continue
            parts = ([f"{point} - base"] if per_point else []) + [str(i) for i in index]
            names.append(f"o{k}[{', '.join(parts or ['0'])}]")
    return names


def _bound_name(name, params):
    """The generated loop's local holding the pair argument ``name`` (prefixed: never a loop variable)."""
    return f"p__{name}" if name in params else f"i__{name}"


def _loop_source(template, name, outputs, dim, symmetric, indent, params=(), inputs=(), arguments=(),
                 planar=False, reach_test=True, own_indent=8, split=False):
    """Source of one loop: a's terms summed in registers ``ta*``, global terms in ``tg*``.

    ``params`` and ``inputs`` are unpacked once from the loop's ``params``/``inp`` tuples (in the
    declared order); the pair function is called with ``arguments`` (its data, in its signature's order).
    ``planar`` (``dim`` 3): points in the plane z = 0; the loop reads x and y, passes ``d2 = 0.0`` (a constant
    the compiler folds into the pair function) and leaves the z components of spatial outputs alone.
    ``reach_test`` False (a list walk of an interaction whose terms vanish beyond the reach,
    :class:`PairInteraction`'s ``support``): every listed pair is computed, without the test ``r2 < reach2``.
    ``own_indent``: the indentation of the lines that start and store a point's sums. ``split``: a point's listed
    terms in three passes (:func:`_terms`; for a symmetric interaction without the reach test).
    """
    own = _targets(outputs, True, "a", planar)
    other = _targets(outputs, True, "b", planar)
    glob_t = _targets(outputs, False, None)
    pad = "\n" + " " * indent
    read = 2 if planar else dim
    d = "(" + "".join(f"d{c}, " for c in range(dim)) + ")"
    minus_d = "(" + "".join(f"-d{c}, " for c in range(dim)) + ")"
    data = "".join(f", {_bound_name(n, params)}" for n in arguments)
    unpack = [f"({''.join(_bound_name(n, params) + ', ' for n in names)}) = {tup}"
              for names, tup in ((params, "params"), (inputs, "inp")) if names]
    lines = []
    kept = [i for i, t in enumerate(own) if t is not None]
    if symmetric:
        lines.append(f"ta, tb, tg = pair(a, b, r2, {d}{data})")
        lines += [f"ta{i} += ta[{i}]" for i in kept]
        lines += [f"{t} += tb[{i}]" for i, t in enumerate(other) if t is not None]
        lines += [f"tg{i} += tg[{i}]" for i in range(len(glob_t))]
    else:
        lines.append(f"ta, tg = pair(a, b, r2, {d}{data})")
        lines += [f"ta{i} += ta[{i}]" for i in kept]
        lines += [f"tg{i} += tg[{i}]" for i in range(len(glob_t))]
        lines.append(f"tb, tg = pair(b, a, r2, {minus_d}{data})")
        lines += [f"{t} += tb[{i}]" for i, t in enumerate(other) if t is not None]
        lines += [f"tg{i} += tg[{i}]" for i in range(len(glob_t))]
    pad_a = "\n" + " " * own_indent
    pad_t = "\n" + " " * 4
    terms, scratch = _terms(split, own_indent, lines, own, other, glob_t, read, dim, data, reach_test)
    return template.format(
        terms=terms,
        scratch=scratch,
        name=name,
        views=pad_t.join([f"o{k} = out[{k}]" for k in range(len(outputs))] + unpack),
        # each thread zeroes its own buffers at the start of its chunk (in parallel)
        zero_buffers=pad_t.join(f"o{k}[:] = 0.0" for k in range(len(outputs))),
        zero_buffers_nested=("\n" + " " * 8).join(f"o{k}[:] = 0.0" for k in range(len(outputs))),
        zero_global=pad_t.join(f"tg{i} = 0.0" for i in range(len(glob_t))) or "pass",
        store_global=pad_t.join(f"{t} += tg{i}" for i, t in enumerate(glob_t)) or "pass",
        store_global_early=("\n" + " " * 12).join(f"{t} += tg{i}" for i, t in enumerate(glob_t)) or "pass",
        load_a="; ".join(f"xa{c} = x_sc[a, {c}]" for c in range(read)),
        zero_own=pad_a.join(f"ta{i} = 0.0" for i in kept) or "pass",
        store_own=pad_a.join(f"{own[i]} += ta{i}" for i in kept) or "pass",
        diff=pad.join([f"d{c} = x_sc[b, {c}] - xa{c}" for c in range(read)]
                      + [f"d{c} = 0.0" for c in range(read, dim)]),
        scan_diff=("\n" + " " * 16).join(f"e{c} = x_sc[b, {c}] - xa{c}" for c in range(read)),
        # the plain build's listing of the points of one bin (its candidates' coordinates in flat_x)
        load_point="; ".join(f"u{c} = x_sc[a, {c}]" for c in range(read)),
        read=read,
        flat_store="; ".join(f"flat_x[{c}, nc] = x_sc[b, {c}]" for c in range(read)),
        flat_diff="; ".join(f"e{c} = flat_x[{c}, q] - u{c}" for c in range(read)),
        diff_first="; ".join(f"e{c} = x_sc[b, {c}] - u{c}" for c in range(read)),
        norm_first=" + ".join(f"e{c} * e{c}" for c in range(read)),
        norm2=" + ".join(f"d{c} * d{c}" for c in range(read)),
        reach_test=(f"if r2 >= reach2:{pad}    continue" if reach_test
                    else "pass  # no test: every term vanishes beyond the reach (PairInteraction's support)"),
        body=pad.join(lines),
    )


def _terms(split, indent, body, own, other, glob_t, read, dim, data, reach_test):
    """``(terms, scratch)``: the source of the terms of a point's listed partners ``pair_j[begin:stop]`` (its first
    line at ``indent``; the walk's and the fused builds', so that a build sums what a walk of its list sums, bit for
    bit) and of the scratch it needs (at the loop's start).

    One pass (``split`` False): per partner the difference, the pair function, a's terms summed, b's added to b.
    Split (a symmetric interaction whose terms vanish beyond the reach, so no test per pair): three passes, the
    differences gathered into the scratch ``sd``, the pair function mapped over them with a's terms summed and b's
    kept in the scratch ``st`` (no gather, no scatter: the compiler's vector loop, its sums reassociated, see
    :func:`_compile`), then b's terms added to b in the list's order."""
    d = "(" + "".join(f"d{c}, " for c in range(dim)) + ")"
    if not split:
        lines = (["for p in range(begin, stop):", "    b = pair_j[p]"]
                 + [f"    d{c} = x_sc[b, {c}] - xa{c}" for c in range(read)]
                 + [f"    d{c} = 0.0" for c in range(read, dim)]
                 + ["    r2 = " + " + ".join(f"d{c} * d{c}" for c in range(read))]
                 + (["    if r2 >= reach2:", "        continue"] if reach_test else [])
                 + [f"    {line}" for line in body])
        return ("\n" + " " * indent).join(lines), "pass"
    kept = [i for i, t in enumerate(own) if t is not None]
    kept_b = [(i, t) for i, t in enumerate(other) if t is not None]
    n_b = max(len(kept_b), 1)
    lines = ["m = stop - begin", "if m > sd.shape[1]:", f"    sd = np.empty(({read}, 2 * m))",
             f"    st = np.empty(({n_b}, 2 * m))",
             "for q in range(m):", "    b = pair_j[begin + q]"]
    lines += [f"    sd[{c}, q] = x_sc[b, {c}] - xa{c}" for c in range(read)]
    lines += ["for q in range(m):", "    b = pair_j[begin + q]"]
    lines += [f"    d{c} = sd[{c}, q]" for c in range(read)] + [f"    d{c} = 0.0" for c in range(read, dim)]
    lines += ["    r2 = " + " + ".join(f"d{c} * d{c}" for c in range(read)),
              f"    ta, tb, tg = pair(a, b, r2, {d}{data})"]
    lines += [f"    ta{i} += ta[{i}]" for i in kept]
    lines += [f"    st[{j}, q] = tb[{i}]" for j, (i, _) in enumerate(kept_b)]
    lines += [f"    tg{i} += tg[{i}]" for i in range(len(glob_t))]
    lines += ["for q in range(m):", "    b = pair_j[begin + q]"]
    lines += [f"    {t} += st[{j}, q]" for j, (_, t) in enumerate(kept_b)]
    scratch = f"sd = np.empty(({read}, 64))\n    st = np.empty(({n_b}, 64))"  # grown when a point has more partners
    return ("\n" + " " * indent).join(lines), scratch


def _core_stamp():
    """Short hash of what the generated loops inline from the core (templates, bin helpers).

    It is part of each loop's name, hence of its numba cache file: numba's cache checks only
    the time stamp of the file a function is compiled against (the physics file), so without
    it a change of the core would leave stale loops in the caches of the methods' files.
    """
    text = _LIST_TEMPLATE + _SCAN_TEMPLATE + _BUILD_TEMPLATE + _BUILD_PLAIN_TEMPLATE + SCAN_SOURCE \
        + inspect.getsource(_terms) + repr(SPLIT_FASTMATH)
    return hashlib.sha1(text.encode()).hexdigest()[:8]


_CORE_STAMP = None
SPLIT_FASTMATH = {"reassoc"}  # the split terms' floating-point flags (_terms): sums in any order, nothing else


def _data_names(py_func):
    """The pair function's data: its argument names after ``(a, b, r2, d)``."""
    names = list(inspect.signature(py_func).parameters)
    if names[:4] != ["a", "b", "r2", "d"]:
        raise TypeError(f"{py_func.__name__}: a pair function's arguments start with (a, b, r2, d), got {names[:4]}")
    return names[4:]


def _stamp(*values):
    return hashlib.sha1(repr(values).encode()).hexdigest()[:8]


def _specialise(pair, constants, kernel):
    """``pair`` re-compiled from its source with ``constants`` (arguments, removed from its signature)
    and the kernel's closed forms (``kernel_profile``, ``kernel_derivatives``) bound as globals:
    numba treats globals as compile-time constants, so a branch on a bool constant is pruned.

    Returns ``(dispatcher, arguments)``, the arguments left to pass. Without anything to bind,
    ``pair`` itself.
    """
    py_func = pair.py_func
    arguments = [n for n in _data_names(py_func) if n not in constants]
    if not constants and kernel is None:
        return pair, arguments
    suffix = (f"{kernel.key}_" if kernel is not None else "") + _stamp(sorted(constants.items(), key=str))
    bind = dict(constants, **(kernel.closed_forms() if kernel is not None else {}))
    return recompiled(pair, f"{py_func.__name__}__{suffix}", bind, drop=constants, inline="always"), arguments


def _compile(pair, template, kind, outputs, dim, symmetric, params=(), inputs=(), arguments=(), planar=False,
             reach_test=True):
    global _CORE_STAMP
    if _CORE_STAMP is None:
        _CORE_STAMP = _core_stamp()
    base = pair.py_func.__name__
    # the declared order of params/inputs is part of the loop's bytecode; the stamp keeps the name unique
    space = "planar" if planar else f"{dim}d"
    name = f"_{kind}{'' if reach_test else '_all'}_{'sym' if symmetric else 'gather'}_{space}_{_CORE_STAMP}__{base}"
    indent = 16 if kind in ("scan", "build_plain") else 12
    # a list's terms (the walk's, a build's) in three passes, _terms, for a symmetric interaction without the reach test
    split = symmetric and not reach_test and kind != "scan"
    source = _loop_source(template, name, outputs, dim, symmetric, indent, params, inputs, arguments, planar,
                          reach_test, own_indent=12 if kind == "build_plain" else 8, split=split)
    namespace = {"pair": pair, "np": np, **SCAN_HELPERS}  # the bin-stencil helpers (their source is in the stamp)
    # compiled against the physics function's file: numba's disk cache then keys the loop by
    # that file (its time stamp) and by the loop's own bytecode
    exec(compile(source, inspect.getfile(pair.py_func), "exec"), namespace)  # noqa: S102
    function = namespace[name]
    function.__module__ = pair.py_func.__module__
    # nogil: the chunks of one evaluation run at once on a thread pool (see PairInteraction.compute); the split terms
    # (_terms) reassociate their sums, so that the compiler vectorises the pass of the pair function
    return numba.njit(cache=True, nogil=True, **({"fastmath": SPLIT_FASTMATH} if split else {}))(function), source


_SCRATCH = {}  # per thread (and "stacked"): the one float array the pair loops' buffers are views of
RELEASE_MIN_POINTS = 500_000
"""Sums over at least this many points (particles and ghosts) give their scratch pages, gathered inputs and the
heap's free pages back to the system after each sum (:meth:`PairInteraction.compute`): at 1e6 particles that keeps
ALARIC 2D near 600 bytes per particle. Below it they are kept: re-faulting the pages and ``malloc_trim`` cost
20-25 % of a step at 1e4 particles (ALARIC 2D, BISPH; interleaved A/B in one process), where the memory is small;
at 1e6 (ALARIC 2D) about 7 %."""


def release_scratch():
    """Give the pages of the pair loops' scratch back to the system (:func:`~ase_sphrelax.neighbors.release_pages`;
    they read as zeros and are written again by the next sum): for a method whose peak memory lies outside its
    pair sums."""
    for buf in _SCRATCH.values():
        release_pages(buf)


def _scratch(key, size):
    """A float64 array of ``size`` elements from the scratch of ``key``, grown (never shrunk) on demand;
    only the interaction being computed uses it."""
    buf = _SCRATCH.get(key)
    if buf is None or buf.shape[0] < size:
        _SCRATCH[key] = None  # the old one goes first
        buf = _SCRATCH[key] = np.empty(size)
    return buf


def _carve(flat, shapes):
    """Consecutive views of ``flat`` with the given shapes (a tuple)."""
    views, pos = [], 0
    for shape in shapes:
        size = int(np.prod(shape))
        views.append(flat[pos:pos + size].reshape(shape))
        pos += size
    return tuple(views)


def _names(what, names):
    """A declaration as a tuple of names."""
    if isinstance(names, str) or not all(isinstance(n, str) for n in names):
        raise TypeError(f"{what} must be a tuple of argument names, got {names!r}")
    return tuple(names)


def _by_name(interaction, what, declared, given):
    """The values of ``given`` (a dict) in the ``declared`` order; a one-line error for a missing or unknown name."""
    given = {} if given is None else given
    fname = interaction.pair.py_func.__name__
    if not isinstance(given, Mapping):
        raise TypeError(f"{what} of {fname} must be a dict by name {declared}, got {type(given).__name__}")
    for name in given:
        if name not in declared:
            raise ValueError(f"{what}: {fname} has no {what[:-1]} {name!r} (declared: {declared})")
    for name in declared:
        if name not in given:
            raise ValueError(f"{what}: {fname} needs {name!r} (declared: {declared})")
    return tuple(given[name] for name in declared)


class PairInteraction:
    """Per-pair physics turned into list walks and bin scans (see the module docstring).

    Parameters
    ----------
    pair : numba dispatcher
        ``pair(a, b, r2, d, <data>)``, jitted with ``inline="always"``, returning
        ``(terms_a, terms_b, terms_global)`` (symmetric) or ``(terms_a, terms_global)`` (gather);
        ``<data>`` are argument names, each declared in exactly one of ``params``, ``inputs``,
        ``constants``.
    outputs : dict of str to Output
        The accumulators, in the order of ``out``.
    params : tuple of str
        Global parameters (numbers, small arrays), passed by name to :meth:`compute`.
    inputs : tuple of str
        Per-particle arrays (N, ...), passed by name to :meth:`compute` and gathered to the
        sorted extended points.
    symmetric : bool
        True: called once per pair, writes both partners. False: written for a gathering
        from b, called for both orientations.
    dim : int
        Number of stored coordinates (3 for ASE positions; any D for point sets of higher
        dimension walked over a stored list).
    constants : dict or None
        Arguments fixed at construction and compiled in (a flag gives its flat form).
    support : str or None
        The name of a parameter ``inv_h`` beyond whose support every term of the pair function is exactly zero:
        ``r >= 1 / inv_h`` (the kernel placeholders at ``q = r inv_h``). When the reach of a call is at least that
        support (``reach * inv_h >= 1``, to 1e-12), a stored list is walked without the test ``r < reach``: the
        entries of the list's skin add zeros (a pair at r = h whose r rounds just below the support adds less than
        1e-40 of the scale), and the walk has no branch that goes either way at random (Fan's walk at 1e6 in 2D:
        0.93x the CPU time). None (default): the test on every entry.

    Raises
    ------
    ValueError
        When the declaration does not match the pair function's signature (the name is given).
    """

    def __init__(self, pair, outputs, params=(), inputs=(), symmetric=True, dim=3, constants=None, support=None):
        if not hasattr(pair, "py_func"):
            raise TypeError(f"pair must be a numba.njit function, got {type(pair).__name__}")
        if not outputs:
            raise ValueError("outputs: an interaction needs at least one accumulator")
        self.pair = pair
        self.params = _names("params", params)
        if support is not None and support not in self.params:
            raise ValueError(f"support must name one of the params {self.params} (1 / the support radius), "
                             f"got {support!r}")
        self.support = support
        self.inputs = _names("inputs", inputs)
        self.constants = dict(constants or {})
        fname = pair.py_func.__name__
        arguments = _data_names(pair.py_func)
        declared = list(self.params) + list(self.inputs) + list(self.constants)
        for name in declared:
            if declared.count(name) > 1:
                raise ValueError(f"{fname}: {name!r} is declared more than once in params/inputs/constants")
            if name not in arguments:
                raise ValueError(f"{fname} has no argument {name!r} (its data are {arguments})")
        for name in arguments:
            if name not in declared:
                raise ValueError(f"{fname}: argument {name!r} is declared in none of params, inputs, constants")
        self.uses_kernel = any(name in pair.py_func.__code__.co_names for name in KERNEL_FUNCTIONS)
        self.outputs = {name: (o if isinstance(o, Output) else Output(tuple(o))) for name, o in outputs.items()}
        self.symmetric = bool(symmetric)
        self.dim = int(dim)
        self._pairs = {}
        self._loops = {}
        self._stacked = None

    def __repr__(self):
        kind = "symmetric" if self.symmetric else "gather"
        return (f"PairInteraction({self.pair.py_func.__name__}, {kind}, params={self.params}, inputs={self.inputs}, "
                f"outputs={list(self.outputs)})")

    def _kernel(self, kernel):
        if not self.uses_kernel:
            return None
        if kernel is None:
            raise ValueError(f"kernel: {self.pair.py_func.__name__} calls a kernel placeholder "
                             f"({', '.join(KERNEL_FUNCTIONS)}): pass compute(..., kernel=Kernel)")
        if not hasattr(kernel, "closed_forms"):
            raise TypeError(f"kernel must be a Kernel (ase_sphrelax.kernels.get_kernel), got {type(kernel).__name__}")
        return kernel

    def specialised(self, kernel=None):
        """The pair function with its constants and ``kernel`` bound (compiled on first use)."""
        kernel = self._kernel(kernel)
        key = None if kernel is None else kernel.key
        if key not in self._pairs:
            self._pairs[key] = _specialise(self.pair, self.constants, kernel)
        return self._pairs[key]

    def loop(self, kind, kernel=None, planar=False, reach_test=True):
        """The generated loop over one chunk of points, compiled on first use: ``kind`` "list"
        (walk a stored list), "scan" (one-shot bin scan) or "build" (bin scan that also writes
        the Verlet list of a pending build, see :meth:`NeighborList.fused_build`; "build_plain" for points that
        are all originals with one cut-off and no wide points, see :meth:`NeighborList.plain`), for ``kernel``
        when the pair function calls a kernel placeholder; ``planar``: for points in the plane z = 0
        (see :meth:`compute`); ``reach_test`` False: a list walk that computes every listed pair (only for an
        interaction with a ``support``, see the class docstring)."""
        return self._loop_entry(kind, kernel, planar, reach_test)[0]

    def _loop_entry(self, kind, kernel, planar, reach_test):
        kernel = self._kernel(kernel)
        planar = bool(planar) and self.dim == 3
        reach_test = bool(reach_test) or kind == "scan"
        if not reach_test and self.support is None:
            raise ValueError(f"reach_test=False needs an interaction with a support, {self!r} has none")
        key = (kind, None if kernel is None else kernel.key, planar, reach_test)
        if key not in self._loops:
            template = {"list": _LIST_TEMPLATE, "scan": _SCAN_TEMPLATE, "build": _BUILD_TEMPLATE,
                        "build_plain": _BUILD_PLAIN_TEMPLATE}[kind]
            pair, arguments = self.specialised(kernel)
            self._loops[key] = _compile(pair, template, kind, list(self.outputs.values()), self.dim, self.symmetric,
                                        self.params, self.inputs, arguments, planar, reach_test)
        return self._loops[key]

    def source(self, kind="list", kernel=None, planar=False, reach_test=True):
        """Python source of a generated loop (for reading and debugging)."""
        return self._loop_entry(kind, kernel, planar, reach_test)[1]

    def _reach_covers_support(self, params, reach):
        """True when every pair beyond ``reach`` lies beyond the support too (``reach * inv_h >= 1``, to 1e-12)."""
        if self.support is None:
            return False
        inv_h = params[self.params.index(self.support)]
        return float(reach) * float(inv_h) >= 1.0 - 1e-12

    def _thread_buffers(self, nthreads, n_ext, forward):
        """Per-thread accumulators ``buffers[t][k]``: views of one scratch array per thread that every
        interaction shares (:func:`_scratch`), reused between calls (each loop chunk zeroes its own
        thread's buffers). The outputs are folded into new arrays before :meth:`compute` returns, so
        the scratch is free again: a method of several interactions (density, pressure, viscosity)
        keeps one set of buffers, not one per interaction.

        With ``forward`` neighbours thread t writes only the rows from ``partner_starts()[t]``
        on (its chunk's first point, as in :class:`NeighborList`'s half lists and scans, or
        lower for points of wide reach); :meth:`compute` passes it views that start there:
        on 2 threads about 1.5 instead of 2 rows per point to zero and fold. Otherwise every
        thread has all rows (views of one stacked array).
        """
        outputs = list(self.outputs.values())
        if forward:  # pages are touched only as far as a view reaches
            self._stacked = None
            shapes = [(n_ext,) + o.shape if o.per_point else (max(o.size, 1),) for o in outputs]
            return [_carve(_scratch(t, sum(int(np.prod(sh)) for sh in shapes)), shapes) for t in range(nthreads)]
        shapes = [(nthreads, n_ext) + o.shape if o.per_point else (nthreads, max(o.size, 1)) for o in outputs]
        self._stacked = _carve(_scratch("stacked", sum(int(np.prod(sh)) for sh in shapes)), shapes)
        return [tuple(stack[t] for stack in self._stacked) for t in range(nthreads)]

    def compute(self, neighbors, positions, params=None, inputs=None, reach=None, kernel=None, consume_inputs=False,
                planar=False, keep_scratch=False, out=None):
        """Run the interaction over every pair within ``reach``; return the folded outputs.

        Parameters
        ----------
        neighbors : NeighborList
            Updated for ``positions`` (in either state: stored list or one-shot bins), or
            any object of the same interface (``extend``, ``gather``, ``loop_arrays``,
            ``fold_threads``).
        positions : ndarray (N, D)
        params : dict of str
            The declared parameters by name (numbers, small arrays).
        inputs : dict of str to ndarray
            The declared per-particle arrays (N, ...) by name, gathered to the sorted extended points.
        reach : float or None
            Largest interaction distance (default: the neighbour list's largest cut-off).
        kernel : Kernel or None
            The kernel bound to the pair function's placeholders (required when it calls one).
        consume_inputs : bool
            True: ``inputs`` is emptied once its arrays are gathered (arrays made for the call, referenced by the
            dict only, are freed before the pair loop's buffers are made).
        planar : bool
            True when every position has z = 0 (a 2D system, :func:`ase_sphrelax.checks.resolve_dim`): the loops
            read x and y only and leave the z components of :attr:`Output.spatial` outputs at zero. The pair
            function must give a zero z component for them when ``d[2] = 0`` (its spatial inputs, if any, lie in
            the plane too).
        keep_scratch : bool
            True: the threads' accumulators keep their pages after a large sum (:data:`RELEASE_MIN_POINTS`), for a
            method whose peak memory lies inside its pair sums, where they are in use anyway (Fan in 2D: the same peak,
            and 0.97x the CPU time of a relaxation step that faults them in again; in 3D SPHLBFGS's step peaked
            higher with them kept). False (default): given back, so that a later peak outside the sums (ALARIC's H
            solve, an optimiser's step) does not hold them.
        out : dict of str to ndarray, optional
            Per-point outputs to write into by name (overwritten; float64, C-contiguous, writeable, shape
            ``(N,) + shape`` of the output): e.g. a calculator's previous forces array that no one else holds, whose
            pages are in memory already (at 1e6 particles a fresh array's pages cost more than the fold that fills
            them). The others are fresh arrays.

        Returns
        -------
        PairResult
            Per-point outputs folded onto particles, shape (N,) + shape; global outputs
            summed over threads.
        """
        params = _by_name(self, "params", self.params, params)
        given, inputs = inputs, _by_name(self, "inputs", self.inputs, inputs)
        self._kernel(kernel)  # a missing kernel fails before any work
        release = len(positions) >= RELEASE_MIN_POINTS
        if release:
            release_free_memory()  # the caller's freed arrays: not held (as the heap's pages) through this sum's peak
        x_sc = neighbors.extend(positions)
        inp = tuple(neighbors.gather(values, slot=k) for k, values in enumerate(inputs))
        inputs = None
        if consume_inputs and given is not None:
            given.clear()
        given = None
        reach = neighbors.max_cutoff if reach is None else float(reach)
        n_ext = x_sc.shape[0]
        nthreads = thread_count(n_ext)
        forward = bool(getattr(neighbors, "forward_pairs", False))
        buffers = self._thread_buffers(nthreads, n_ext, forward)
        bases = [0] * nthreads
        if forward:
            bases = neighbors.partner_starts(nthreads) if hasattr(neighbors, "partner_starts") else \
                [first for first, _ in chunk_bounds(n_ext, nthreads)]
        ends = None
        if forward and nthreads > 1 and not getattr(neighbors, "build_pending", False) \
                and hasattr(neighbors, "partner_ends"):
            ends = neighbors.partner_ends(nthreads)  # None unless a stored list is walked
        if forward:
            # thread t's pairs reach rows [bases[t], ends[t]) only: zero and fold no more
            ends = ends or [n_ext] * nthreads
            buffers = [tuple(buf[: ends[t] - bases[t]] if o.per_point else buf
                             for buf, o in zip(buffers[t], self.outputs.values())) for t in range(nthreads)]
        per_thread = [(buffers[t], bases[t]) for t in range(nthreads)]
        reach_test = not self._reach_covers_support(params, reach)
        pending = bool(getattr(neighbors, "build_pending", False))
        plain = bool(getattr(neighbors, "plain", False))
        one_shot = not pending and plain and hasattr(neighbors, "one_shot_scan") \
            and neighbors.loop_arrays()[0] == "scan"
        if pending or one_shot:
            # a rebuild: one bin scan writes the Verlet list and evaluates the pairs; one-shot plain bins: the plain
            # build's loop, its partners listed into a region it writes over (no list kept)
            loop = self.loop("build_plain" if plain else "build", kernel, planar, reach_test=reach_test)
            pre = (x_sc, *neighbors.build_arrays())
            post = (reach * reach, tuple(params), inp)

            def scan(t, count_s, pair_j, pos, first, last):
                return loop(*pre, count_s, pair_j, pos, *post, *per_thread[t], first, last)

            (neighbors.fused_build if pending else neighbors.one_shot_scan)(scan, nthreads)
        else:
            kind, arrays = neighbors.loop_arrays()
            loop = self.loop(kind, kernel, planar, reach_test=reach_test)
            run_chunks(loop, n_ext, (x_sc, *arrays, reach * reach, tuple(params), inp), per_thread=per_thread)
        result = self._fold(neighbors, buffers, bases, forward, out)
        self._stacked = buffers = per_thread = None  # views of the shared scratch: not kept past the call
        if release or n_ext >= RELEASE_MIN_POINTS:
            if not keep_scratch:  # not held through the next sum's peak (the H solve's update)
                release_scratch()
            if hasattr(neighbors, "release_gathered"):  # the gathered inputs: not held through the next sum's peak
                neighbors.release_gathered()
            release_free_memory()
        return result

    def _fold_into(self, out, point_k, neighbors):
        """The arrays (N, size) the fold writes, one per per-point output (None: fresh), from ``out`` by name; None
        when ``out`` names none."""
        if not out:
            return None
        n = neighbors.n_particles
        outputs = list(self.outputs.items())
        unknown = sorted(set(out) - {outputs[k][0] for k in point_k})
        if unknown:
            raise ValueError(f"out: per-point outputs of {self!r} expected, got {unknown[0]!r}")
        arrays = []
        for k in point_k:
            name, output = outputs[k]
            given = out.get(name)
            if given is not None:  # C-contiguous: the reshape is a view, which the fold writes through
                given = check_fold_output(given, (n,) + output.shape, f"out[{name!r}]").reshape(n, max(output.size, 1))
            arrays.append(given)
        return arrays

    def _fold(self, neighbors, buffers, bases, forward, out=None):
        result = PairResult()
        outputs = list(self.outputs.items())
        point_k = [k for k, (_, o) in enumerate(outputs) if o.per_point]
        if point_k:
            into = self._fold_into(out, point_k, neighbors)
            given = {} if into is None else {"outs": into}  # a neighbour set of an older interface takes none
            if forward:  # per-thread buffers of their own lengths
                parts = [tuple(buffers[t][k].reshape(buffers[t][k].shape[0], max(outputs[k][1].size, 1))
                               for t in range(len(buffers))) for k in point_k]
                folded = neighbors.fold_thread_parts(parts, np.asarray(bases, dtype=np.int64), **given)
            else:
                stacked = self._stacked
                folded = neighbors.fold_threads([stacked[k].reshape(stacked[k].shape[0], stacked[k].shape[1], -1)
                                                 for k in point_k], **given)
            for k, values in zip(point_k, folded):
                name, shape = outputs[k][0], (values.shape[0],) + outputs[k][1].shape
                if out and out.get(name) is not None:
                    result[name] = out[name]  # the given array itself, written through its (n, size) view
                elif values.shape == shape:
                    result[name] = values  # the array itself, not a view of it (its owner is the result)
                else:
                    result[name] = values.reshape(shape)
        for k, (name, output) in enumerate(outputs):
            if not output.per_point:
                result[name] = sum(buffers[t][k] for t in range(len(buffers)))
        return result
