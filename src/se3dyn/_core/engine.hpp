// The assembler and the Newton iteration of one generalized-alpha step (Eqs. (38)-(46)).
//
// The assembler knows no element type: it updates the frames of the iterate (Eq. (38)), asks
// every element batch for its residual, constraint and tangent contributions (which they add
// through the frame maps of frames.hpp into the residual and into the fixed block pattern), and
// forms the blocks of the stabilised index-2 matrix that are products of element blocks
// (`VelProd`, `XiProd`: -(cM M + cC C_T) B_n^T and -B B_n^T).  The Newton loop and its modified
// Newton strategy are written once here, for every kind of run.
#pragma once
#include <algorithm>
#include <cmath>
#include <limits>
#include <functional>
#include <vector>

#include <map>
#include <memory>
#include <stdexcept>
#include <utility>

#include "elements/registry.hpp"
#include "pool.hpp"
#include "sparse_lu.hpp"

namespace se3dyn {

// target (k_i x 6) -= Vel block (k_i x k_j) * (B_n A)_{joint, slot}^T
struct VelProd {
  long target, src;  // offsets in the values; src in velv once the engine is set up
  int ki, kj, joint, slot;
};
// target (6 x 6) -= (B A)_{c1, s1} (6 x k) * (B_n A)_{c2, s2}^T
struct XiProd {
  long target;
  int k, c1, s1, c2, s2;
};

// t (r x 6, ld 6) -= X Y^T, X (r x k, ld ldx), Y (6 x k, ld 6): every entry the sum over l in
// increasing order from 0 that the plain triple loop forms, here with the six columns of a row
// side by side (through Y^T, k x 6), which the compiler vectorises
inline void sub_times_T(int r, int k, const double* X, int ldx, const double* Y, double* t) {
  double YT[36];
  for (int l = 0; l < k; ++l)
    for (int c = 0; c < 6; ++c) YT[6 * l + c] = Y[6 * c + l];
  for (int i = 0; i < r; ++i) {
    double s[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    for (int l = 0; l < k; ++l) {
      const double x = X[ldx * i + l];
      for (int c = 0; c < 6; ++c) s[c] += x * YT[6 * l + c];
    }
    for (int c = 0; c < 6; ++c) t[6 * i + c] -= s[c];
  }
}

struct Engine {
  Engine() = default;
  Engine(const Engine&) = delete;  // owns its element batches
  Engine& operator=(const Engine&) = delete;
  FrameTables T;
  std::vector<std::unique_ptr<ElementBatch>> batches;  // one per element type, in order
  Joints* joints = nullptr;  // the constraint elements (their B blocks serve index 2)
  int nq = 0, nm = 0, nu = 0;
  long nvals = 0;         // values of the index-3 pattern
  long nvals2 = 0;        // values of the index-2 pattern (extra blocks after the index-3 ones)
  // relative coordinates: frames whose coordinates are log coordinates (non-abelian joints)
  std::vector<int> log_f;              // frames
  std::vector<Frame> log_H0inv;        // H_J0^-1
  std::vector<double> log_Apinv;       // (., 6, 6)
  std::vector<char> log_needed;        // a spring needs them inside the iterations
  std::vector<VelProd> velprod;
  std::vector<XiProd> xiprod;
  // the split iteration's xi block B_n B_n^T is symmetric: the products of joint pairs c1 <= c2
  // (xi_half), the blocks of c1 > c2 their transposes (xi_mirror: source, target offsets)
  std::vector<int> xi_half;
  std::vector<std::pair<long, long>> xi_mirror;
  // products of two constant slots of B (node B, joint frame: Joints::constant_slots) are the
  // same at every evaluation: -X Y^T of product i at xi_neg[36 * xi_at[i]] (xi_at[i] < 0: a
  // product to form), made at the first evaluation with products
  std::vector<int> xi_at;
  std::vector<double> xi_neg;
  // the value ranges [first, last) the split iteration's matrix writes: all but the constraint
  // rows' blocks and the dynamic rows' xi blocks, which it leaves alone (and zero: Stepper)
  std::vector<std::pair<long, long>> split_ranges;
  std::vector<char> is_joint_frame;    // (F,)
  // driven coordinates (nd, DRIVE): unknown, kind (0 position, 1 velocity), input slots of
  // the position (-1 for a velocity driver), the rate and the acceleration
  // (se3dyn.engine.layout._drive_table)
  // PID laws (joint_force.hpp): per controlled coordinate the input slot of its state
  // (z_n, e_n, h/2: 3 slots), written by the time loop (Stepper::controller_inputs)
  std::vector<int> ctrl_slot;
  std::vector<double> ctrl_ts;  // (npid,) sample time of a sampled law, 0 for a continuous one
  std::vector<int> ctrl_dof;    // (npid,) the controlled unknown
  int npid() const { return int(ctrl_slot.size()); }
  // contacts (elements/contact.hpp): per contact the first input slot of its state (CSTATE
  // numbers and h/2), the states in ctrl after the PID states' (Stepper::controller_inputs)
  std::vector<int> cs_slot;
  static constexpr int CSTATE = 19;  // (elements/contact.hpp: 9 state numbers, 10 outputs)
  int ncs() const { return int(cs_slot.size()); }
  // the states a step carries (State.ctrl): 2 per PID law, CSTATE per contact
  long nctrl() const { return 2L * npid() + long(CSTATE) * ncs(); }
  // couplings alpha_b = ratio alpha_a + offset (se3dyn.ModelBuilder.coupling): per coupling
  // the leader's and the follower's unknowns, the ratio and the offset; the merges of the
  // follower's matrix column and row into the leader's, (src, dst) values and factor, columns
  // first, for the index-3 and the index-2 matrix (se3dyn.engine.layout)
  std::vector<int> cpl_lead, cpl_follow;
  std::vector<double> cpl_ratio, cpl_offset;
  std::vector<long> merge3, merge2;  // (., 2) src, dst
  std::vector<double> mfac3, mfac2;
  int ncpl() const { return int(cpl_lead.size()); }
  // Laws of the user's (se3dyn.ModelBuilder.joint(torque=lambda t, q, v: ...)): a callback
  // evaluated once per evaluation, before the element kernels, on the calling thread, with the
  // time (input slot law_t), the iterate's coordinates and velocities (nq); it writes per law
  // its force (k), d force / d q (k x k) and d force / d v (k x k) to law_out, which the joint
  // force kernel reads (joint_force.hpp). A probe fills law_out with generic numbers instead.
  std::function<void(double, const double*, const double*, double*)> law_cb;
  std::vector<double> law_out;
  int law_t = -1;
  bool law_probe = false;
  static constexpr int DRIVE = 5;
  std::vector<int> drive;
  int ndrive() const { return int(drive.size() / DRIVE); }
  // the velocity-level blocks the products use (Context::vel): offsets in the values,
  // increasing, and in velv
  std::vector<long> vel_off, vel_at;
  // Element colours (colour()). A batch's elements go in chunks of CHUNK consecutive ones
  // (chunk k: elements CHUNK k .. CHUNK (k+1) - 1, fewer in the last). No two chunks of one
  // colour add to the same frame with unknowns, hence to the same residual, constraint or
  // matrix entry, so the chunks of a colour may be evaluated in any number of parts at once;
  // the colours follow each other, and a chunk's elements go in order. Every evaluation adds
  // the contributions in this order, so the numbers do not depend on the thread count.
  static constexpr int CHUNK = 32;
  struct Colours {
    std::vector<int> chunk;  // chunk numbers, a colour after the other
    std::vector<int> start;  // where colour c starts in chunk, with the end last
  };
  std::vector<Colours> colours;
  size_t joint_batch = 0;  // batches[joint_batch] is joints
  // Items of a list grouped by the block they add to: groups in the order of their first item,
  // the items of a group in list order (item[ptr[g] .. ptr[g+1])). The groups may go in parts
  // on the pool, and every block receives its terms in list order.
  struct Groups {
    std::vector<int> ptr{0}, item;
    Groups() = default;
    explicit Groups(const std::vector<long>& target) {
      std::map<long, int> group;
      std::vector<int> of(target.size());
      for (size_t i = 0; i < target.size(); ++i)
        of[i] = group.emplace(target[i], int(group.size())).first->second;
      ptr.assign(group.size() + 1, 0);
      for (int g : of) ++ptr[g + 1];
      for (size_t g = 0; g < group.size(); ++g) ptr[g + 1] += ptr[g];
      item.resize(target.size());
      std::vector<int> next(ptr.begin(), ptr.end() - 1);
      for (size_t i = 0; i < target.size(); ++i) item[next[of[i]]++] = int(i);
    }
    long size() const { return long(ptr.size()) - 1; }
    template <class Fn>
    void each(long min_part, Fn&& fn) const {
      each_index(size(), min_part, [&](long g) {
        for (int q = ptr[g]; q < ptr[g + 1]; ++q) fn(item[q]);
      });
    }
  };
  Groups vel_groups, xi_groups;  // of velprod, and of xi_half (the split's products)
  // work
  FrameState S;
  std::vector<Frame> Hn;
  std::vector<double> velv;  // (the velocity-level blocks only)

  void add_batch(const std::string& key, const Tables& t) {
    std::unique_ptr<ElementBatch> b = make_batch(key);
    b->load(t);
    if (key == "joint") joints = static_cast<Joints*>(b.get());
    batches.push_back(std::move(b));
  }

  // Greedy colouring of each batch's chunks by the frames with unknowns their elements add to
  // (ElementBatch::frames_of): chunk k takes the lowest colour no earlier chunk of its frames
  // has. A chain's joints and bodies take two colours (neighbouring chunks share a node).
  void colour() {
    colours.assign(batches.size(), Colours());
    std::vector<std::vector<int>> at(T.F);  // colours already at each frame
    std::vector<int> frs, mine, taken;
    for (size_t b = 0; b < batches.size(); ++b) {
      const ElementBatch& B = *batches[b];
      for (auto& a : at) a.clear();
      const int nch = (B.n + CHUNK - 1) / CHUNK;
      std::vector<int> col(nch, 0);
      int ncol = 0;
      for (int k = 0; k < nch; ++k) {
        mine.clear();
        for (int e = CHUNK * k; e < std::min(B.n, CHUNK * (k + 1)); ++e) {
          B.frames_of(e, frs);
          for (int f : frs)
            if (f >= 0 && f < T.F && T.dof[f] >= 0) mine.push_back(f);
        }
        std::sort(mine.begin(), mine.end());
        mine.erase(std::unique(mine.begin(), mine.end()), mine.end());
        taken.clear();
        for (int f : mine) taken.insert(taken.end(), at[f].begin(), at[f].end());
        std::sort(taken.begin(), taken.end());
        int c = 0;
        for (int t : taken)
          if (t == c) ++c;
          else if (t > c) break;
        col[k] = c;
        ncol = std::max(ncol, c + 1);
        for (int f : mine) at[f].push_back(c);
      }
      Colours& C = colours[b];
      C.start.assign(ncol + 1, 0);
      for (int k = 0; k < nch; ++k) ++C.start[col[k] + 1];
      for (int c = 0; c < ncol; ++c) C.start[c + 1] += C.start[c];
      C.chunk.resize(nch);
      std::vector<int> next(C.start.begin(), C.start.end() - 1);
      for (int k = 0; k < nch; ++k) C.chunk[next[col[k]]++] = k;
    }
  }

  // Parts of a loop over `count` items of which each part should have at least `min_part`
  static int parts_for(long count, long min_part) {
    long p = std::min<long>(Pool::get().threads(), count / std::max(1L, min_part));
    return int(std::max(1L, std::min(p, 64L)));
  }

  // fn(i) for i in [0, count), in parts of at least min_part on the pool: for loops whose
  // iterations write disjoint entries
  template <class Fn>
  static void each_index(long count, long min_part, Fn&& fn) {
    int parts = parts_for(count, min_part);
    Pool::get().run(parts, [&](int p) {
      for (long i = count * p / parts; i < count * (p + 1) / parts; ++i) fn(i);
    });
  }

  // fn(e) for the elements e of batch b, a colour after the other (Colours), each colour's
  // chunks in parts of at least min_chunks on the pool
  template <class Fn>
  void each_element(size_t b, long min_chunks, Fn&& fn) const {
    const Colours& C = colours[b];
    const int n = batches[b]->n;
    for (size_t c = 0; c + 1 < C.start.size(); ++c) {
      const int first = C.start[c];
      each_index(C.start[c + 1] - first, min_chunks, [&](long q) {
        const int k = C.chunk[first + q];
        for (int e = CHUNK * k; e < std::min(n, CHUNK * (k + 1)); ++e) fn(e);
      });
    }
  }

  void setup() {
    S.resize(T.F);
    Hn.resize(T.F);
    // velv holds the distinct sources of the products, in the order of their offsets
    std::vector<std::pair<long, long>> src;  // (offset in the values, size)
    for (const VelProd& p : velprod) src.emplace_back(p.src, long(p.ki) * p.kj);
    std::sort(src.begin(), src.end());
    src.erase(std::unique(src.begin(), src.end()), src.end());
    long nv = 0;
    for (const auto& [off, size] : src) {
      vel_off.push_back(off);
      vel_at.push_back(nv);
      nv += size;
    }
    velv.assign(nv, 0.0);
    for (VelProd& p : velprod)
      p.src = vel_at[std::lower_bound(vel_off.begin(), vel_off.end(), p.src) - vel_off.begin()];
    std::map<std::pair<int, int>, long> target_of;  // (c1, c2) -> its block's offset
    for (size_t i = 0; i < xiprod.size(); ++i) {
      const XiProd& p = xiprod[i];
      target_of[{p.c1, p.c2}] = p.target;
      if (p.c1 <= p.c2) xi_half.push_back(int(i));
    }
    for (const auto& [cc, t] : target_of)
      if (cc.first < cc.second) xi_mirror.emplace_back(t, target_of.at({cc.second, cc.first}));
    if (!joints) {  // no constraint elements: an empty batch keeps the index-2 code uniform
      batches.push_back(std::make_unique<Joints>());
      joints = static_cast<Joints*>(batches.back().get());
    }
    std::vector<std::pair<long, long>> skip;
    for (const VelProd& p : velprod) skip.emplace_back(p.target, p.target + 6L * p.ki);
    for (int e = 0; e < joints->n; ++e) {
      int fr[3] = {joints->fa[e], joints->fb[e], joints->fj[e]};
      long off[3] = {joints->off_ca[e], joints->off_cb[e], joints->off_cj[e]};
      for (int s = 0; s < 3; ++s)
        if (T.k[fr[s]] > 0 && off[s] >= 0) skip.emplace_back(off[s], off[s] + 6L * T.k[fr[s]]);
    }
    std::sort(skip.begin(), skip.end());
    long at = 0;
    for (const auto& [a, b] : skip) {
      if (a > at) split_ranges.emplace_back(at, a);
      at = std::max(at, b);
    }
    if (nvals2 > at) split_ranges.emplace_back(at, nvals2);
    colour();
    for (size_t b = 0; b < batches.size(); ++b)
      if (batches[b].get() == joints) joint_batch = b;
    std::vector<long> targets;
    for (const VelProd& p : velprod) targets.push_back(p.target);
    vel_groups = Groups(targets);
    targets.clear();
    for (int i : xi_half) targets.push_back(xiprod[i].target);
    xi_groups = Groups(targets);
  }

  void load_frames(const double* H4) {
    for (int f = 0; f < T.F; ++f) frame_from4(H4 + 16 * f, Hn[f]);
  }

  // Frames of the iterate: H = H_n exp(A n) (Eq. (38)), T(A n) A (Eq. (27)), v* = A v, vd* = A vd
  void update_frames(const double* n, const double* v, const double* vd, bool tangent) {
    int parts = parts_for(T.F, 256);
    Pool::get().run(parts, [&](int p) {
      update_frames(n, v, vd, tangent, int(long(T.F) * p / parts), int(long(T.F) * (p + 1) / parts));
    });
  }
  void update_frames(const double* n, const double* v, const double* vd, bool tangent, int f0,
                     int f1) {
    for (int f = f0; f < f1; ++f) {
      int d = T.dof[f];
      if (d < 0) {
        S.H[f] = Hn[f];
        continue;
      }
      double ns[6];
      frame_expand(T, f, n + d, ns);
      frame_expand(T, f, v + d, &S.v[6 * f]);
      frame_expand(T, f, vd + d, &S.vd[6 * f]);
      Frame E;
      if (tangent) {
        double T6[36];
        exp_tangent_se3(ns, E, T6);
        frame_cols(T, f, T6, &S.TA[36 * f]);
      } else {
        exp_se3(ns, E);
      }
      compose(Hn[f], E, S.H[f]);
    }
  }

  // alpha = alpha_n + n on abelian joint unknowns (Eq. (60)); log coordinates where asked
  void coordinates(const double* alpha_n, const double* n, double* alpha, bool all_logs) const {
    for (int f = 0; f < T.F; ++f) {
      if (!is_joint_frame[f] || T.dof[f] < 0) continue;
      int d = T.dof[f];
      for (int c = 0; c < T.k[f]; ++c) alpha[d + c] = alpha_n[d + c] + n[d + c];
    }
    for (size_t i = 0; i < log_f.size(); ++i) {
      if (!(all_logs || log_needed[i])) continue;
      int f = log_f[i], d = T.dof[f];
      Frame G;
      compose(log_H0inv[i], S.H[f], G);
      double l[6];
      log_se3(G, l);
      for (int c = 0; c < T.k[f]; ++c) {
        double s = 0.0;
        for (int j = 0; j < 6; ++j) s += log_Apinv[36 * i + 6 * c + j] * l[j];
        alpha[d + c] = s;
      }
    }
  }

  struct Out {
    double* r;       // (nq,)
    double* phi;     // (nm,)
    double* psi;     // (nm,) or nullptr
    double* alpha;   // (nq,)
    double* vals;    // (nvals or nvals2,) or nullptr
    double* energy;  // (N_ENERGY,) or nullptr
    double* arhs = nullptr;  // (nm,) acceleration-level constraint right-hand side or nullptr
    double* ctrl = nullptr;  // (2 npid,) PID states of the iterate (joint_force.hpp) or nullptr
    // the matrix of the split index-2 iteration (newton.hpp) instead of the full one: without
    // the dynamic rows' xi blocks -(cM M + cC C_T) B_n^T and the constraint rows
    // (Context::phi_rows), the xi block as B_n B_n^T (symmetric: half the products)
    bool split = false;
  };

  // Residual (Eq. (39)), constraints (Eq. (40)), velocity constraints and, when vals, the
  // scaled iteration matrix with coefficients (cM, cC, cK) of M, C_T and K_T T; returns the
  // force scale. Frames of the step start must be loaded (load_frames).
  double evaluate(const double* alpha_n, const double* n, const double* v, const double* vd,
                  const double* lam, const double* u, double cM, double cC, double cK,
                  bool index2, double cv, bool all_logs, Out o) {
    update_frames(n, v, vd, o.vals != nullptr);
    coordinates(alpha_n, n, o.alpha, all_logs);
    if (law_cb && !law_probe && !law_out.empty()) law_cb(u[law_t], o.alpha, v, law_out.data());
    std::fill(o.r, o.r + nq, 0.0);
    std::fill(o.phi, o.phi + nm, 0.0);
    if (o.psi) std::fill(o.psi, o.psi + nm, 0.0);
    long nv = index2 ? nvals2 : nvals;
    if (o.vals) {
      int parts = parts_for(nv, 1L << 16);
      Pool::get().run(parts, [&](int p) {
        long lo = nv * p / parts, hi = nv * (p + 1) / parts;
        if (!o.split) {
          std::fill(o.vals + lo, o.vals + hi, 0.0);
          return;
        }
        for (const auto& [a, b] : split_ranges)
          if (b > lo && a < hi) std::fill(o.vals + std::max(a, lo), o.vals + std::min(b, hi), 0.0);
      });
    }
    bool prod = o.vals && index2;
    bool vprod = prod && !o.split;
    if (vprod) std::fill(velv.begin(), velv.end(), 0.0);
    if (o.energy) std::fill(o.energy, o.energy + N_ENERGY, 0.0);
    Context X;
    X.T = &T;
    X.S = &S;
    X.coords = o.alpha;
    X.law = law_out.empty() ? nullptr : law_out.data();
    X.vq = v;
    X.vdq = vd;
    X.lam = lam;
    X.u = u;
    X.gravity = u;  // u[0:3] is gravity (se3dyn.engine.inputs._Inputs)
    X.r = o.r;
    X.phi = o.phi;
    X.psi = o.psi;
    X.vals = o.vals;
    X.velv = vprod ? velv.data() : nullptr;
    X.vel_off = vel_off.data();
    X.vel_at = vel_at.data();
    X.nvel = long(vel_off.size());
    X.cM = cM;
    X.cC = cC;
    X.cK = cK;
    X.phi_rows = !o.split;
    X.energy = o.energy;
    X.ctrl = o.ctrl;
    X.arhs = o.arhs;
    if (o.arhs) std::fill(o.arhs, o.arhs + nm, 0.0);
    joints->cv_ = cv;
    // index2: the matrix (when asked) is the stabilised index-2 one, which needs psi
    if (prod && !o.psi) throw std::invalid_argument("index-2 matrix without velocity constraints");
    joints->constant_slots(T);
    for (size_t b = 0; b < batches.size(); ++b) eval_batch(b, X, prod);
    if (prod) {
      each_element(joint_batch, 2, [&](int e) { joints->store_B0(T, Hn, joints->Bnu, e); });
      double* vals = o.vals;
      if (vprod)
        vel_groups.each(64, [&](int i) {
          const VelProd& p = velprod[i];
          const double* V = velv.data() + p.src;  // ki x kj row-major (src: in velv)
          const double* Bn = &joints->Bnu[108 * p.joint + 36 * p.slot];  // 6 x kj, ld 6
          sub_times_T(p.ki, p.kj, V, p.kj, Bn, vals + p.target);  // target: ki x 6
        });
      if (xi_at.empty()) constant_products();
      // target -= B_{c1,s1} B_{c2,s2}^T (B: of the iterate, or for the split at the step start)
      auto product = [&](int i, const std::vector<double>& B1) {
        const XiProd& p = xiprod[i];
        double* t = vals + p.target;
        if (xi_at[i] >= 0) {
          const double* c = &xi_neg[36L * xi_at[i]];
          for (int q = 0; q < 36; ++q) t[q] += c[q];
        } else {
          sub_times_T(6, p.k, &B1[108 * p.c1 + 36 * p.s1], 6,
                      &joints->Bnu[108 * p.c2 + 36 * p.s2], t);
        }
      };
      if (!o.split) {
        for (size_t i = 0; i < xiprod.size(); ++i) product(int(i), joints->Bu);
      } else {  // (the targets of xi_mirror are distinct)
        xi_groups.each(64, [&](int i) { product(xi_half[i], joints->Bnu); });
        each_index(long(xi_mirror.size()), 256, [&](long i) {
          const auto& [from, to] = xi_mirror[i];
          for (int r = 0; r < 6; ++r)
            for (int c = 0; c < 6; ++c) vals[to + 6 * r + c] = vals[from + 6 * c + r];
        });
      }
    }
    return X.fscale;
  }

  // The contributions of batch b's elements, a colour after the other, each colour's chunks
  // in parts on the pool (Colours). Each chunk sums its energies and powers apart and the
  // chunks' sums are added in the order of the chunks, so that these sums, like every other
  // entry, do not depend on the number of parts.
  std::vector<double> chunk_energy;  // (chunks of a colour, N_ENERGY)
  void eval_batch(size_t b, Context& X, bool prod) {
    const ElementBatch& B = *batches[b];
    const Colours& C = colours[b];
    for (size_t c = 0; c + 1 < C.start.size(); ++c) {
      const int first = C.start[c], chunks = C.start[c + 1] - first;
      const int parts = parts_for(chunks, 1);
      if (X.energy) chunk_energy.assign(size_t(N_ENERGY) * chunks, 0.0);
      double fs[64];
      Pool::get().run(parts, [&](int p) {
        Context Y = X;
        Y.fscale = 0.0;
        for (int q = int(long(chunks) * p / parts); q < int(long(chunks) * (p + 1) / parts); ++q) {
          const int k = C.chunk[first + q];
          if (X.energy) Y.energy = &chunk_energy[size_t(N_ENERGY) * q];
          B.eval(Y, prod, Span{CHUNK * k, std::min(B.n, CHUNK * (k + 1))});
        }
        fs[p] = Y.fscale;
      });
      for (int p = 0; p < parts; ++p) X.fscale = std::fmax(X.fscale, fs[p]);
      if (X.energy)
        for (int q = 0; q < chunks; ++q)
          for (int i = 0; i < N_ENERGY; ++i) X.energy[i] += chunk_energy[size_t(N_ENERGY) * q + i];
    }
  }

  // The products of two constant slots (slot 0, node A, is the only one that moves: B A =
  // Ad_{(X_A H_J)^-1} A_A), once; the same numbers as sub_times_T forms (0 - s = -s exactly)
  void constant_products() {
    xi_at.assign(xiprod.size(), -1);
    int nc = 0;
    for (size_t i = 0; i < xiprod.size(); ++i)
      if (xiprod[i].s1 > 0 && xiprod[i].s2 > 0) xi_at[i] = nc++;
    xi_neg.assign(36L * nc, 0.0);
    for (size_t i = 0; i < xiprod.size(); ++i) {
      const XiProd& p = xiprod[i];
      if (xi_at[i] >= 0)
        sub_times_T(6, p.k, &joints->Bnu[108 * p.c1 + 36 * p.s1], 6,
                    &joints->Bnu[108 * p.c2 + 36 * p.s2], &xi_neg[36L * xi_at[i]]);
    }
    if (xiprod.empty()) xi_at.push_back(-1);  // (made)
  }

  // out (nm) += B A x, x (nq) on the unknowns, with the B A of the last matrix evaluation
  // (the split index-2 iteration, newton.hpp)
  void add_BA(const double* x, double* out) const {
    each_element(joint_batch, 4, [&](int e) {
      int fr[3] = {joints->fa[e], joints->fb[e], joints->fj[e]};
      double o[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
      for (int s = 0; s < 3; ++s) {
        int f = fr[s], d = T.dof[f], k = T.k[f];
        if (d < 0) continue;
        if (s == 2 && T.select[f]) {  // B A of the joint frame: A (B_J = I), a selection
          for (int c = 0; c < k; ++c) o[T.sel[6 * f + c]] += x[d + c];
          continue;
        }
        const double* BA = &joints->Bu[108 * e + 36 * s];  // 6 x k, ld 6
        if (k == 6) add_rows<6>(BA, x + d, o);
        else if (k == 3) add_rows<3>(BA, x + d, o);
        else
          for (int i = 0; i < 6; ++i)
            for (int c = 0; c < k; ++c) o[i] += BA[6 * i + c] * x[d + c];
      }
      double* out_e = out + joints->mult[e];
      for (int i = 0; i < 6; ++i) out_e[i] += o[i];
    });
  }
  template <int K>
  static void add_rows(const double* BA, const double* x, double* o) {
    for (int i = 0; i < 6; ++i) {
      double acc = 0.0;
      for (int c = 0; c < K; ++c) acc += BA[6 * i + c] * x[c];
      o[i] += acc;
    }
  }

  // B_n^T xi on the unknowns: out[dof_f] -= A_f^T B_{n,f}^T xi (the index-2 correction)
  void subtract_BnT(const double* xi, double* out) const {
    each_element(joint_batch, 4, [&](int e) {
      int fr[3] = {joints->fa[e], joints->fb[e], joints->fj[e]};
      const double* x = xi + joints->mult[e];
      for (int s = 0; s < 3; ++s) {
        int f = fr[s], d = T.dof[f];
        if (d < 0) continue;
        const int k = T.k[f];
        if (s == 2 && T.select[f] && !T.pframe[f]) {  // (B_n A of the joint frame: A, a selection)
          for (int c = 0; c < k; ++c) out[d + c] -= x[T.sel[6 * f + c]];
          continue;
        }
        const double* Bn = &joints->Bnu[108 * e + 36 * s];  // 6 x k
        if (k == 6) sub_cols<6>(Bn, x, out + d);
        else if (k == 3) sub_cols<3>(Bn, x, out + d);
        else
          for (int c = 0; c < k; ++c) {
            double acc = 0.0;
            for (int i = 0; i < 6; ++i) acc += Bn[6 * i + c] * x[i];
            out[d + c] -= acc;
          }
      }
    });
  }
  template <int K>
  static void sub_cols(const double* Bn, const double* x, double* out) {
    for (int c = 0; c < K; ++c) {
      double acc = 0.0;
      for (int i = 0; i < 6; ++i) acc += Bn[6 * i + c] * x[i];
      out[c] -= acc;
    }
  }
};

}  // namespace se3dyn
