// What an element kernel sees and writes at one Newton iterate.
#pragma once
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "../frames.hpp"

namespace se3dyn {

// Energies and powers of a state: kinetic (Eq. (47)), gravity potential, elastic energy
// (Eq. (62) and the elastic elements), and the powers of actuators (incl. control laws),
// external loads and dissipation (Eq. (64) and the dampers of the elements).
enum Energy { KINETIC = 0, POTENTIAL, ELASTIC, P_ACTUATOR, P_LOADS, P_DISSIPATION, N_ENERGY };

// Round-off floor of the force scale: a force computed as the difference of large terms (a
// stiffness times positions or coordinates far from zero) carries a round-off of about eps
// times the terms, whatever the net force. An element reports ROUNDOFF_SCALE times those terms
// as a force magnitude (Context::scale), which keeps the relative residual tolerances (1e-10
// by default) some 50 times above that round-off instead of asking Newton for digits that do
// not exist (e.g. a spring at its reference, a steel beam carrying a few newtons).
constexpr double ROUNDOFF_SCALE = 1e-4;

struct Context {
  const FrameTables* T;
  const FrameState* S;
  const double* coords;  // (nq,) relative coordinates alpha (Eq. (60)) on joint unknowns
  const double* vq;      // (nq,) velocities v
  const double* vdq = nullptr;  // (nq,) accelerations vd
  const double* lam;     // (nm,) multipliers
  const double* u;       // (nu,) time-dependent inputs at the iterate's time
  const double* gravity; // (3,) = u[0:3]
  double* r;             // (nq,) residual of Eq. (39), accumulated
  double* phi;           // (nm,) constraints Eq. (55)
  double* psi;           // (nm,) velocity constraints (index 2) or nullptr
  double* arhs = nullptr;  // (nm,) right-hand side of the acceleration-level constraints
  double* vals;          // iteration-matrix values (block storage) or nullptr
  double* velv;          // velocity-level part cM M + cC C_T (index 2) or nullptr: the blocks
                         // the index-2 products use, at vel_at[i] for the block at vel_off[i]
  const long* vel_off = nullptr;  // (nvel,) their offsets in vals, increasing
  const long* vel_at = nullptr;   // (nvel,) their offsets in velv
  long nvel = 0;
  double cM = 0, cC = 0, cK = 0;  // coefficients of M, C_T and K_T T (Eq. (46))
  // with vals: also the constraint rows (Eq. (59)); the split index-2 iteration of
  // _core/newton.hpp does without them (the constraints' rows there are B, of the multiplier
  // columns' blocks)
  bool phi_rows = true;
  double fscale = 0;     // magnitude of the forces entering r (for relative tolerances)
  double* energy;        // (N_ENERGY,) or nullptr
  double* ctrl = nullptr;
  const double* law = nullptr;  // (.,) the user's laws' forces and tangents (engine.hpp)  // (2 npid,) PID states (z, e) of the iterate (joint_force.hpp) or nullptr

  // Where the velocity-level block at offset `off` of vals goes: into velv, or nowhere
  // (nullptr: not an index-2 matrix, or a block no index-2 product uses)
  double* vel(long off) const {
    if (!velv) return nullptr;
    const long* p = std::lower_bound(vel_off, vel_off + nvel, off);
    return p != vel_off + nvel && *p == off ? velv + vel_at[p - vel_off] : nullptr;
  }

  void scale(const double* g, int n) {
    for (int i = 0; i < n; ++i) fscale = std::fmax(fscale, std::fabs(g[i]));
  }
};

// The arrays of one element type by field name (filled from se3dyn.elements.<type>.tables)
struct Tables {
  virtual ~Tables() = default;
  virtual std::vector<double> real(const char* key) const = 0;
  virtual std::vector<long> integer(const char* key) const = 0;
  template <class T>
  std::vector<T> ints(const char* key) const {
    std::vector<long> v = integer(key);
    return std::vector<T>(v.begin(), v.end());
  }
  std::vector<Frame> frames(const char* key) const {
    std::vector<double> h = real(key);
    std::vector<Frame> out(h.size() / 16);
    for (size_t i = 0; i < out.size(); ++i) frame_from4(&h[16 * i], out[i]);
    return out;
  }
};

// The elements one call of a kernel evaluates: first .. last-1 (engine.hpp: a chunk of
// consecutive elements)
struct Span {
  int first, last;
};

// A batch of elements of one type (struct of arrays): its kernel adds the residual, constraint
// and tangent contributions of the elements of a span at one iterate
// (se3dyn/_core/elements/*.hpp). Kernels write only through the Context (Context::fscale,
// energy) and into the entries of their elements' frames, so that the assembler may evaluate
// elements that share no frame concurrently (Engine::colour).
struct ElementBatch {
  int n = 0;
  virtual ~ElementBatch() = default;
  virtual void load(const Tables& t) = 0;
  // the frames element e adds to (its unknowns' rows and columns)
  virtual void frames_of(int e, std::vector<int>& out) const = 0;
  virtual void eval(Context& X, bool index2, Span span) const = 0;
};

}  // namespace se3dyn
