// Python bindings of the compiled engine (nanobind): the element tables arrive once from
// se3dyn.engine.layout as a dict of numpy arrays; evaluations and steps work on numpy arrays in place.
#include <nanobind/nanobind.h>
#include <nanobind/stl/optional.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <tuple>

#include "block_pattern.hpp"
#include "joint_tree.hpp"
#include "newton.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace se3dyn {
Series& series() {
  static Series s;
  return s;
}
}  // namespace se3dyn

using namespace se3dyn;

using DArr = nb::ndarray<double, nb::c_contig, nb::device::cpu>;        // written
using CArr = nb::ndarray<const double, nb::c_contig, nb::device::cpu>;  // read (may be read-only)
using IArr = nb::ndarray<int64_t, nb::c_contig, nb::device::cpu>;
using I32Arr = nb::ndarray<int32_t, nb::c_contig, nb::device::cpu>;

namespace {

nb::object item(const nb::dict& d, const char* key) {
  if (!d.contains(key)) throw std::invalid_argument(std::string("engine table missing: ") + key);
  return d[key];
}
std::vector<double> dvec(const nb::dict& d, const char* key) {
  DArr a = nb::cast<DArr>(item(d, key));
  return std::vector<double>(a.data(), a.data() + a.size());
}
template <class T>
std::vector<T> ivec(const nb::dict& d, const char* key) {
  IArr a = nb::cast<IArr>(item(d, key));
  std::vector<T> out(a.size());
  for (size_t i = 0; i < a.size(); ++i) out[i] = static_cast<T>(a.data()[i]);
  return out;
}
std::vector<Frame> frames(const nb::dict& d, const char* key) {
  std::vector<double> h = dvec(d, key);
  std::vector<Frame> out(h.size() / 16);
  for (size_t i = 0; i < out.size(); ++i) frame_from4(&h[16 * i], out[i]);
  return out;
}
double* ptr(DArr& a, size_t n, const char* what) {
  if (a.size() != n)
    throw std::invalid_argument(std::string(what) + ": expected " + std::to_string(n) +
                                " values, got " + std::to_string(a.size()));
  return a.data();
}
const double* cptr(const CArr& a, size_t n, const char* what) {
  if (a.size() != n)
    throw std::invalid_argument(std::string(what) + ": expected " + std::to_string(n) +
                                " values, got " + std::to_string(a.size()));
  return a.data();
}

struct DictTables : Tables {
  nb::dict d;
  explicit DictTables(nb::dict x) : d(std::move(x)) {}
  std::vector<double> real(const char* key) const override { return dvec(d, key); }
  std::vector<long> integer(const char* key) const override { return ivec<long>(d, key); }
};

void build(Engine& E, const nb::dict& d) {
  E.nq = nb::cast<int>(item(d, "nq"));
  E.nm = nb::cast<int>(item(d, "nm"));
  E.nu = nb::cast<int>(item(d, "nu"));
  E.nvals = nb::cast<long>(item(d, "nvals"));
  E.nvals2 = nb::cast<long>(item(d, "nvals2"));
  FrameTables& T = E.T;
  T.dof = ivec<int>(d, "frame_dof");
  T.k = ivec<int>(d, "frame_k");
  T.node = ivec<char>(d, "frame_node");
  T.A = dvec(d, "frame_A");
  T.F = static_cast<int>(T.dof.size());
  T.classify();
  E.is_joint_frame = ivec<char>(d, "frame_joint");
  E.drive = ivec<int>(d, "drive");  // (nd, Engine::DRIVE)
  E.ctrl_slot = ivec<int>(d, "ctrl_slot");  // (npid,)
  E.ctrl_ts = dvec(d, "ctrl_ts");            // (npid,) sample times, 0: continuous
  E.ctrl_dof = ivec<int>(d, "ctrl_dof");     // (npid,) controlled unknowns
  E.cs_slot = ivec<int>(d, "cs_slot");       // (ncs,) contacts' state slots
  E.law_out.assign(nb::cast<long>(item(d, "law_size")), 0.0);  // (the user's laws)
  E.law_t = nb::cast<int>(item(d, "law_t"));
  E.cpl_lead = ivec<int>(d, "cpl_lead");
  E.cpl_follow = ivec<int>(d, "cpl_follow");
  E.cpl_ratio = dvec(d, "cpl_ratio");
  E.cpl_offset = dvec(d, "cpl_offset");
  E.merge3 = ivec<long>(d, "merge3");
  E.merge2 = ivec<long>(d, "merge2");
  E.mfac3 = dvec(d, "mfac3");
  E.mfac2 = dvec(d, "mfac2");
  T.prescribed.assign(E.nq, 0);
  T.pframe.assign(T.F, 0);
  for (int i = 0; i < E.ndrive(); ++i) T.prescribed[E.drive[Engine::DRIVE * i]] = 1;
  for (int b : E.cpl_follow) T.prescribed[b] = 1;  // (a follower: like a driven unknown)
  for (int f = 0; f < T.F; ++f)
    for (int c = 0; c < T.k[f]; ++c) T.pframe[f] |= T.driven(f, c);
  for (nb::handle h : nb::cast<nb::list>(item(d, "elements"))) {
    nb::tuple kt = nb::cast<nb::tuple>(h);
    E.add_batch(nb::cast<std::string>(kt[0]), DictTables(nb::cast<nb::dict>(kt[1])));
  }
  E.log_f = ivec<int>(d, "log_frame");
  E.log_H0inv = frames(d, "log_H0inv");
  E.log_Apinv = dvec(d, "log_Apinv");
  E.log_needed = ivec<char>(d, "log_needed");
  std::vector<long> vp = ivec<long>(d, "velprod");  // (., 6): target, src, ki, kj, joint, slot
  for (size_t i = 0; i + 5 < vp.size(); i += 6)
    E.velprod.push_back({vp[i], vp[i + 1], int(vp[i + 2]), int(vp[i + 3]), int(vp[i + 4]),
                         int(vp[i + 5])});
  std::vector<long> xp = ivec<long>(d, "xiprod");  // (., 6): target, k, c1, s1, c2, s2
  for (size_t i = 0; i + 5 < xp.size(); i += 6)
    E.xiprod.push_back({xp[i], int(xp[i + 1]), int(xp[i + 2]), int(xp[i + 3]), int(xp[i + 4]),
                        int(xp[i + 5])});
  E.setup();
}

// The tables of a JointTree (joint_tree.hpp) from se3dyn.analysis._jointtree.tree_tables.
JointTree joint_tree(const nb::dict& d) {
  JointTree J;
  J.nq = nb::cast<int>(item(d, "nq"));
  J.nv = nb::cast<int>(item(d, "nv"));
  J.par = ivec<int>(d, "parent");
  J.kind = ivec<int>(d, "kind");
  J.k = ivec<int>(d, "k");
  J.qadr = ivec<int>(d, "qadr");
  J.vadr = ivec<int>(d, "vadr");
  J.nl = static_cast<int>(J.par.size());
  J.P = frames(d, "P");
  J.Q = frames(d, "Q");
  J.S0 = dvec(d, "S0");
  J.S = dvec(d, "S");
  J.alpha0 = dvec(d, "alpha0");
  J.M = dvec(d, "M");
  J.mc = dvec(d, "mc");
  J.m = dvec(d, "m");
  J.armature = dvec(d, "armature");
  J.K = dvec(d, "stiffness");
  J.ref = dvec(d, "reference");
  J.C = dvec(d, "damping");
  J.qidx = ivec<int>(d, "qidx");
  std::vector<double> g = dvec(d, "gravity");
  for (int i = 0; i < 3; ++i) J.g[i] = g[i];
  return J;
}
// rows of a batch: N when x holds N rows of n finite values (or is empty: zero), else -1
long rows_of(const CArr& x, int n, long N) {
  if (x.size() == 0) return N;
  if (n == 0 || x.size() % n != 0 || (N >= 0 && static_cast<long>(x.size() / n) != N)) return -1;
  for (size_t i = 0; i < x.size(); ++i)
    if (!std::isfinite(x.data()[i])) return -1;
  return static_cast<long>(x.size() / n);
}

}  // namespace

NB_MODULE(_engine, m) {
  m.doc() = "se3dyn compiled engine: element kernels, assembler, Newton step (C++).";
  // engines live in the caches of System objects, which the interpreter may still hold at
  // shutdown (results keep their system): nothing leaks while it runs
  nb::set_leak_warnings(false);
  // compiled for the instruction set of the building machine (CMake option SE3DYN_NATIVE,
  // on by default; an editable build keeps the value of its CMake cache)
#ifdef SE3DYN_BUILT_NATIVE
  m.attr("built_native") = true;
#else
  m.attr("built_native") = false;
#endif
  // threads of the element kernels and frame updates (pool.hpp; se3dyn.set_threads)
  m.def("set_threads", [](int n) { Pool::get().set_threads(n); });
  m.def("threads", [] { return Pool::get().threads(); });
  m.def("set_series", [](DArr c, DArr d, DArr e, DArr f, double cut) {
    Series& S = series();
    S.cut = cut;
    for (int i = 0; i < SERIES_TERMS; ++i) {
      S.c[i] = c.data()[i];
      S.d[i] = d.data()[i];
      S.e[i] = e.data()[i];
      S.f[i] = f.data()[i];
    }
  });

  // The Lie-group kernel of se3dyn.lie, batched over a leading axis (lie.py reshapes): the
  // one implementation of the series-based maps, shared with the element kernels.
  auto batch = [](CArr x, size_t in, size_t out, auto fn) {
    size_t N = x.size() / in;
    if (N * in != x.size()) throw std::invalid_argument("lie: bad input size");
    double* o = new double[std::max<size_t>(N * out, 1)];
    const double* xi = x.data();
    for (size_t i = 0; i < N; ++i) fn(xi + in * i, o + out * i);
    nb::capsule owner(o, [](void* p) noexcept { delete[] static_cast<double*>(p); });
    return nb::ndarray<nb::numpy, double>(o, {N, out}, owner);
  };
  m.def("coefficients", [batch](CArr w) {  // (a, h, c, d, e, f) of |w| (lie.hpp)
    return batch(w, 3, 6, [](const double* a, double* o) {
      Coeffs k = coeffs(a, true);
      o[0] = k.a; o[1] = k.h; o[2] = k.c; o[3] = k.d; o[4] = k.e;
      o[5] = coeff_f(dot3(a, a));
    });
  });
  m.def("exp_se3", [batch](CArr n) {
    return batch(n, 6, 16, [](const double* a, double* o) {
      Frame E;
      exp_se3(a, E);
      frame_to4(E, o);
    });
  });
  m.def("tangent_se3", [batch](CArr n) {
    return batch(n, 6, 36, [](const double* a, double* o) {
      Frame E;
      exp_tangent_se3(a, E, o);
    });
  });
  m.def("tangent_se3_inv", [batch](CArr n) {
    return batch(n, 6, 36, [](const double* a, double* o) { tangent_se3_inv(a, o); });
  });
  m.def("log_se3", [batch](CArr H) {
    return batch(H, 16, 6, [](const double* a, double* o) {
      Frame F;
      frame_from4(a, F);
      log_se3(F, o);
    });
  });
  m.def("exp_so3", [batch](CArr w) {
    return batch(w, 3, 9, [](const double* a, double* o) { exp_so3(a, coeffs(a, false), o); });
  });
  m.def("tangent_so3", [batch](CArr w) {
    return batch(w, 3, 9, [](const double* a, double* o) { tangent_so3(a, o); });
  });
  m.def("tangent_so3_inv", [batch](CArr w) {
    return batch(w, 3, 9, [](const double* a, double* o) { tangent_so3_inv(a, o); });
  });
  m.def("log_so3", [batch](CArr R) {
    return batch(R, 9, 3, [](const double* a, double* o) { log_so3(a, o); });
  });

  nb::class_<Engine>(m, "Engine")
      .def("__init__", [](Engine* E, nb::dict d) {
        new (E) Engine();
        build(*E, d);
      })
      .def_ro("nq", &Engine::nq)
      .def("set_laws",
           [](Engine& E, nb::callable fn) {
             // the user's laws (Engine::law_cb): fn(t, alpha (nq,), v (nq,), out) in Python,
             // called with the GIL (the compiled loop runs without it); an exception there is
             // the callback's to record: it writes NaN, the step fails and says why
             E.law_cb = [fn, &E](double t, const double* alpha, const double* v, double* out) {
               nb::gil_scoped_acquire gil;
               using A = nb::ndarray<nb::numpy, double, nb::ndim<1>>;
               size_t nq = size_t(E.nq), no = E.law_out.size();
               auto view = [](double* p, size_t n) {  // (views, not copies: out is written)
                 return nb::cast(A(p, {n}), nb::rv_policy::reference);
               };
               fn(t, view(const_cast<double*>(alpha), nq), view(const_cast<double*>(v), nq),
                  view(out, no));
             };
           })
      .def_ro("nm", &Engine::nm)
      .def(
          "evaluate",
          [](Engine& E, CArr Hn, CArr alpha_n, CArr n, CArr v, CArr vd, CArr lam, CArr u,
             DArr H, DArr r, DArr phi, DArr alpha, nb::object psi, nb::object vals,
             nb::object energy, double cM, double cC, double cK, bool index2, double cv,
             bool all_logs, nb::object arhs, nb::object ctrl) {
            int F = E.T.F, nq = E.nq, nm = E.nm;
            E.load_frames(cptr(Hn, 16 * F, "Hn"));
            Engine::Out o{ptr(r, nq, "r"), ptr(phi, nm, "phi"), nullptr, ptr(alpha, nq, "alpha"),
                          nullptr, nullptr};
            if (!psi.is_none()) {
              DArr p = nb::cast<DArr>(psi);
              o.psi = ptr(p, nm, "psi");
            }
            if (!vals.is_none()) {
              DArr p = nb::cast<DArr>(vals);
              o.vals = ptr(p, index2 ? E.nvals2 : E.nvals, "vals");
            }
            if (!energy.is_none()) {
              DArr p = nb::cast<DArr>(energy);
              o.energy = ptr(p, N_ENERGY, "energy");
            }
            if (!arhs.is_none()) {
              DArr p = nb::cast<DArr>(arhs);
              o.arhs = ptr(p, nm, "arhs");
            }
            if (!ctrl.is_none()) {  // the PID states (2 npid,) of the iterate
              DArr p = nb::cast<DArr>(ctrl);
              o.ctrl = ptr(p, E.nctrl(), "ctrl");
            }
            double fs = E.evaluate(cptr(alpha_n, nq, "alpha_n"), cptr(n, nq, "n"),
                                   cptr(v, nq, "v"), cptr(vd, nq, "vd"), cptr(lam, nm, "lam"),
                                   cptr(u, E.nu, "u"), cM, cC, cK, index2, cv,
                                   all_logs, o);
            double* Ho = ptr(H, 16 * F, "H");
            for (int f = 0; f < F; ++f) frame_to4(E.S.H[f], Ho + 16 * f);
            return fs;
          },
          "Hn"_a, "alpha_n"_a, "n"_a, "v"_a, "vd"_a, "lam"_a, "u"_a, "H"_a, "r"_a, "phi"_a,
          "alpha"_a, "psi"_a.none(), "vals"_a.none(), "energy"_a.none(), "cM"_a, "cC"_a, "cK"_a,
          "index2"_a, "cv"_a, "all_logs"_a, "arhs"_a.none() = nb::none(),
          "ctrl"_a.none() = nb::none())
      .def("residual_rows", [](Engine& E, CArr H, CArr alpha, CArr v, CArr vd, CArr lam,
                               CArr U, DArr r, long rows) {
        // r (rows, nq): the residual of the equations of motion (Eq. (36)) of every stored row:
        // frames H (rows, F, 4, 4), coordinates, velocities, accelerations, multipliers and
        // inputs of that row (no increment); for the reactions of condensed rigid joints
        int F = E.T.F, nq = E.nq, nm = E.nm, nu = E.nu;
        size_t R = size_t(rows < 0 ? 0 : rows);
        const double* h = cptr(H, R * 16 * F, "H");
        const double *al = cptr(alpha, R * nq, "alpha"), *vv = cptr(v, R * nq, "v"),
                     *aa = cptr(vd, R * nq, "vd"), *ll = cptr(lam, R * nm, "lam"),
                     *uu = cptr(U, R * nu, "U");
        double* ro = ptr(r, R * nq, "r");
        std::vector<double> zero(nq, 0.0), phi(nm), out_alpha(nq);
        for (size_t i = 0; i < R; ++i) {
          E.load_frames(h + i * 16 * F);
          Engine::Out o{ro + i * nq, phi.data(), nullptr, out_alpha.data(), nullptr, nullptr};
          E.evaluate(al + i * nq, zero.data(), vv + i * nq, aa + i * nq, ll + i * nm, uu + i * nu,
                     1.0, 0.0, 0.0, false, 0.0, false, o);
        }
      })
      .def("colours",
           [](const Engine& E) {
             // per element batch, in the order of the tables' elements: (elements, chunks,
             // colours) of Engine::colour
             nb::list out;
             for (size_t b = 0; b < E.batches.size(); ++b)
               out.append(nb::make_tuple(E.batches[b]->n, int(E.colours[b].chunk.size()),
                                         int(E.colours[b].start.size()) - 1));
             return out;
           })
      .def("BnT", [](Engine& E, CArr Hn, CArr xi, DArr out) {
        // out (nq,) = B_n^T xi with B_n the constraint gradient at the frames Hn (Eq. (58))
        E.load_frames(cptr(Hn, 16 * E.T.F, "Hn"));
        E.joints->store_B(E.T, E.Hn, E.joints->Bnu);
        double* o = ptr(out, E.nq, "out");
        std::fill(o, o + E.nq, 0.0);
        E.subtract_BnT(cptr(xi, E.nm, "xi"), o);
        for (int i = 0; i < E.nq; ++i) o[i] = -o[i];
      });

  m.def("block_csc", [](int N, IArr blocks, long nvals, I32Arr colptr, I32Arr rowind,
                        IArr src) {
    // the compressed-column pattern of a matrix of non-overlapping dense blocks (se3dyn.engine.layout
    // Layout.csc): colptr (N+1,), rowind (nvals,), src (nvals,) CSC position -> value
    if (blocks.size() % 5) throw std::invalid_argument("blocks: (nb, 5)");
    if (colptr.size() != size_t(N) + 1 || rowind.size() != size_t(nvals) ||
        src.size() != size_t(nvals))
      throw std::invalid_argument("block_csc: output sizes");
    block_csc(N, blocks.data(), long(blocks.size() / 5), nvals, colptr.data(), rowind.data(),
              src.data());
  });

  nb::class_<Stepper>(m, "Stepper")
      .def("__init__",
           [](Stepper* S, Engine& E, bool index2, int N, IArr blocks, IArr group, IArr drop,
              bool split, bool reference) {
             // the pattern from the blocks of se3dyn.engine.layout (block_pattern.hpp): no pattern
             // arrays per value cross the binding
             new (S) Stepper();
             const long nv = index2 ? E.nvals2 : E.nvals;
             if (blocks.size() % 5) throw std::invalid_argument("blocks: (nb, 5)");
             if (group.size() != size_t(N) && group.size() != 0)
               throw std::invalid_argument("group size");
             if (drop.size() != size_t(E.nm)) throw std::invalid_argument("drop size");
             std::vector<int> gr(group.data(), group.data() + group.size());
             std::vector<char> dr(drop.data(), drop.data() + drop.size());
             std::vector<int> cp(size_t(N) + 1), ri(nv), src(nv);
             block_csc(N, blocks.data(), long(blocks.size() / 5), nv, cp.data(), ri.data(),
                       src.data());
             // (split: the full matrix's pattern again from the blocks, when it is needed)
             std::function<void(std::vector<int>&, std::vector<int>&, std::vector<int>&)> pat;
             if (split && index2)
               pat = [bl = std::vector<int64_t>(blocks.data(), blocks.data() + blocks.size()),
                      N, nv](std::vector<int>& c, std::vector<int>& r, std::vector<int>& v) {
                 c.assign(size_t(N) + 1, 0);
                 r.assign(nv, 0);
                 v.assign(nv, 0);
                 block_csc(N, bl.data(), long(bl.size() / 5), nv, c.data(), r.data(), v.data());
               };
             S->init(&E, index2, N, std::move(cp), std::move(ri), std::move(src),
                     gr.empty() ? nullptr : gr.data(), dr.data(), split, reference,
                     std::move(pat));
           },
           nb::arg("engine"), nb::arg("index2"), nb::arg("N"), nb::arg("blocks"),
           nb::arg("group"), nb::arg("drop"), nb::arg("split") = true,
           nb::arg("reference") = true, nb::keep_alive<1, 2>())
      .def(
          "step",
          [](Stepper& S, CArr Hn, CArr alpha_n, CArr v_n, CArr vd_n, CArr a_n, CArr lam_n,
             CArr u, double h, double am, double af, double g, double b, double tol_r,
             double ltol, double lscale, int max_iter, bool reuse, double kmax, DArr H,
             DArr alpha, DArr v, DArr vd, DArr a, DArr lam, DArr n) {
            Engine& E = *S.E;
            int F = E.T.F, nq = E.nq, nm = E.nm;
            E.load_frames(cptr(Hn, 16 * F, "Hn"));
            Stepper::Params P{h, am, af, g, b, tol_r, ltol, lscale, kmax, max_iter, reuse};
            StepInfo info = S.step(P, cptr(alpha_n, nq, "alpha_n"), cptr(v_n, nq, "v_n"),
                                   cptr(vd_n, nq, "vd_n"), cptr(a_n, nq, "a_n"),
                                   cptr(lam_n, nm, "lam_n"), cptr(u, E.nu, "u"),
                                   ptr(alpha, nq, "alpha"), ptr(v, nq, "v"), ptr(vd, nq, "vd"),
                                   ptr(a, nq, "a"), ptr(lam, nm, "lam"), ptr(n, nq, "n"));
            double* Ho = ptr(H, 16 * F, "H");
            for (int f = 0; f < F; ++f) frame_to4(E.S.H[f], Ho + 16 * f);
            // energies and powers of the converged iterate (the new state), see N_ENERGY
            nb::tuple en = nb::make_tuple(S.energy[0], S.energy[1], S.energy[2], S.energy[3],
                                          S.energy[4], S.energy[5]);
            return nb::make_tuple(info.status, info.iterations, info.residual, info.constraint,
                                  info.factorisations, en);
          })
      .def("lu_stats",
           [](const Stepper& S, const std::string& part) {
             // (n, nnz(L), nnz(U), multiply-adds of a refactorisation, supernodes) of the factors
             // (split index 2: of both, summed, or part "lu" / "xi" of one; the xi block's
             // LDL^T counts its L for L and for U = D L^T, as an LU without pivoting would, and
             // the multiply-adds of its factorisation; n is the factor's order)
             if (part != "all" && part != "lu" && part != "xi")
               throw std::invalid_argument("lu_stats: part 'all', 'lu' or 'xi'");
             const bool lu = part != "xi", xi = part != "lu" && S.split;
             long long l = 0, u = 0, f = 0, n = part == "all" ? S.N : 0;
             int sn = 0;
             if (lu) {
               l += S.lu.nnz_L();
               u += S.lu.nnz_U();
               f += S.lu.refactor_flops();
               sn += S.lu.num_supernodes();
               if (part == "lu") n = S.lu.n();
             }
             if (xi) {
               l += S.lux.nnz_L();
               u += S.lux.nnz_L();
               f += S.lux.factor_flops();
               sn += S.lux.num_supernodes();
               if (part == "xi") n = S.lux.n();
             }
             return nb::make_tuple(n, l, u, f, sn);
           }, nb::arg("part") = "all")
      .def("lu_parts",
           [](const Stepper& S, const std::string& part) {
             // (n, n1, n2) of the iteration matrix's LU (part "lu") or of the split
             // iteration's xi block LDL^T ("xi"): the steps of the two parts its
             // factorisation and solves take at once ([0, n1), [n1, n2); 0, 0: none)
             if (part != "lu" && part != "xi")
               throw std::invalid_argument("lu_parts: part 'lu' or 'xi'");
             auto [n1, n2] = S.lu.parallel_parts();
             if (part == "xi") {
               std::tie(n1, n2) = S.lux.parallel_parts();
               return nb::make_tuple(S.lux.n(), n1, n2);
             }
             return nb::make_tuple(S.lu.n(), n1, n2);
           }, nb::arg("part") = "lu")
      .def("full_steps", [](const Stepper& S) { return S.full_steps; })
      .def("ctrl_into",
           [](const Stepper& S, DArr out) {
             // the PID states (z, e) of the last iterate (2 npid,), see joint_force.hpp
             double* o = ptr(out, S.ctrl_out.size(), "out");
             std::copy(S.ctrl_out.begin(), S.ctrl_out.end(), o);
           })
      .def("sample_jump",
           [](Stepper& S, CArr ctrl_old, CArr v, DArr vd, DArr a, DArr lam) {
             // after a converged step (step()): the switch of the sampled PID laws at its end
             // (Stepper::sample_jump), vd, a, lam in place; returns the power change
             Engine& E = *S.E;
             return S.sample_jump(cptr(ctrl_old, E.nctrl(), "ctrl_old"),
                                  cptr(v, E.nq, "v"), ptr(vd, E.nq, "vd"), ptr(a, E.nq, "a"),
                                  ptr(lam, E.nm, "lam"));
           })
      .def("controller_inputs",
           [](const Stepper& S, CArr ctrl, double h, double t1, DArr u) {
             // u (nu,) with the PID states of ctrl (2 npid,) for a step of size h to t1, in
             // place
             S.controller_inputs(cptr(ctrl, S.E->nctrl(), "ctrl"), h, t1,
                                 ptr(u, S.E->nu, "u"));
           })
      .def("memory_size", [](const Stepper& S) { return S.memory_size(); })
      .def("serials",
           [](const Stepper& S) {
             // (serial number of the solver memory, whether it holds one to keep)
             return nb::make_tuple(S.ref_serial, S.have_ref && !S.ref_probe);
           })
      .def("memory",
           [](const Stepper& S) -> nb::object {
             // the solver memory (the values of the last full factorisation and, split index 2,
             // the mode (newton.hpp); read-only: shared with the stepper, no copy) or None (none,
             // or the generic matrix's: a function of the model)
             if (!S.have_ref || S.ref_probe) return nb::none();
             using Ref = std::shared_ptr<const std::vector<double>>;
             Ref* ref = new Ref(S.ref_vals);
             nb::capsule owner(ref, [](void* p) noexcept { delete static_cast<Ref*>(p); });
             return nb::cast(nb::ndarray<nb::numpy, const double>((*ref)->data(),
                                                                  {(*ref)->size()}, owner));
           })
      .def("holds",
           [](const Stepper& S, std::optional<CArr> ref) {
             return S.holds(ref ? cptr(*ref, S.memory_size(), "ref") : nullptr);
           }, nb::arg("ref").none())
      .def("restore",
           [](Stepper& S, std::optional<CArr> ref) {
             return S.restore(ref ? cptr(*ref, S.memory_size(), "ref") : nullptr);
           }, nb::arg("ref").none())
      .def(
          "solve_values",
          [](Stepper& S, CArr vals, DArr rhs) {
            // factorise the matrix of the values (pattern order; dropped equations replaced by
            // the identity) and solve in place: 0, or the LU's nonzero status
            if (vals.size() != S.vals.size()) throw std::invalid_argument("solve_values: vals");
            if (rhs.size() != size_t(S.N)) throw std::invalid_argument("solve_values: rhs");
            std::copy(vals.data(), vals.data() + vals.size(), S.vals.begin());
            S.apply_merges();
            int code = S.factor();
            if (code == 0) S.solve(rhs.data());
            return code;
          })
      .def(
          "run",
          [](Stepper& S, CArr times, int i0, int i1, int last, CArr U, int output_every,
             double am, double af, double g, double b, double tol_r, double ltol, double lscale,
             int max_iter, bool reuse, double kmax, DArr H, DArr alpha, DArr v, DArr vd, DArr a,
             DArr lam, DArr acc, DArr rt, DArr rH, DArr rv, DArr rvd, DArr rlam, DArr ralpha,
             DArr rscal, long count, DArr ctrl) {
            Engine& E = *S.E;
            int F = E.T.F, nq = E.nq, nm = E.nm;
            long nt = static_cast<long>(times.size());
            if (i0 < 0 || i1 > nt || i0 > i1) throw std::invalid_argument("run: step range");
            cptr(U, static_cast<size_t>(nt * E.nu), "U");
            Stepper::Params P{0.0, am, af, g, b, tol_r, ltol, lscale, kmax, max_iter, reuse};
            Stepper::Carry c{ptr(H, 16 * F, "H"), ptr(alpha, nq, "alpha"), ptr(v, nq, "v"),
                             ptr(vd, nq, "vd"), ptr(a, nq, "a"), ptr(lam, nm, "lam"),
                             ptr(acc, 8, "acc"), ptr(ctrl, E.nctrl(), "ctrl")};
            Stepper::Rows rows;
            rows.cap = static_cast<long>(rt.size());
            rows.count = count;
            rows.M = static_cast<int>(rH.size() / (16 * std::max<long>(rows.cap, 1)));
            rows.t = rt.data();
            rows.H = rH.data();
            rows.v = ptr(rv, rows.cap * nq, "rows v");
            rows.vd = ptr(rvd, rows.cap * nq, "rows vd");
            rows.lam = ptr(rlam, rows.cap * nm, "rows lam");
            rows.alpha = ptr(ralpha, rows.cap * nq, "rows alpha");
            rows.scal = ptr(rscal, rows.cap * 9, "rows scal");
            Stepper::RunResult R;
            {
              nb::gil_scoped_release release;
              R = S.run(P, times.data(), i0, i1, last, U.data(), output_every, c, rows);
            }
            return nb::make_tuple(R.status, R.done, R.iterations, R.factorisations, rows.count,
                                  R.residual, R.constraint);
          });

  // JointSpace's compiled path on trees (joint_tree.hpp): batches of N states, a loop here;
  // False (nothing written) when the sizes do not match or a value is not finite
  nb::class_<JointTree>(m, "JointTree")
      .def("__init__", [](JointTree* J, nb::dict d) { new (J) JointTree(joint_tree(d)); })
      .def_ro("nq", &JointTree::nq)
      .def_ro("nv", &JointTree::nv)
      .def("rnea", [](const JointTree& J, CArr q, CArr v, CArr a, DArr tau) {
        long N = rows_of(q, J.nq, -1);
        if (q.size() == 0 || N < 0 || rows_of(v, J.nv, N) < 0 || rows_of(a, J.nv, N) < 0 ||
            tau.size() != static_cast<size_t>(N * J.nv))
          return false;
        JointTree::Work w(J.nl);
        for (long r = 0; r < N; ++r)
          J.rnea(q.data() + r * J.nq, v.size() ? v.data() + r * J.nv : nullptr,
                 a.size() ? a.data() + r * J.nv : nullptr, tau.data() + r * J.nv, w);
        return true;
      })
      .def("crba", [](const JointTree& J, CArr q, DArr out) {
        long N = rows_of(q, J.nq, -1);
        if (q.size() == 0 || N < 0 || out.size() != static_cast<size_t>(N * J.nv * J.nv))
          return false;
        JointTree::Work w(J.nl);
        for (long r = 0; r < N; ++r) J.crba(q.data() + r * J.nq, out.data() + r * J.nv * J.nv, w);
        return true;
      });
}
