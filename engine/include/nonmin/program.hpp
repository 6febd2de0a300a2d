// The model layer's contract: every model source (planar builder, spatial builder, URDF/MJCF
// robots, SymPy, Python functions) compiles, once at load time, to one Program that the engine
// evaluates at (t, q, qd). The simulation loop, batched evaluation and the derivative code see
// only this interface. Mirrors nonmin.model.Model / ModelTerms / ConstraintTerms (Python):
//
//   M(q) qdd + C(q, qd) qd = f_g(q) + f_p(t, q, qd) + B(q) u + f_c,   A(t, q) qd + φ_t = 0,
//   h = f_g − C qd,   A qdd + γ = 0 with γ = Ȧ qd + 2 φ_tq qd + φ_tt.
//
// All constraint rows of the model are stacked in declaration order (m_all rows); the active set
// is a mask over constraints (`active[c] != 0`), so switching topology never changes sizes.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "types.hpp"

namespace nonmin {

enum class ConstraintKind : int { holonomic = 0, rheonomic = 1, nonholonomic = 2, unilateral = 3 };

// The structural row pattern of A (compressed rows): the columns of row r are
// cols[start[r]] … cols[start[r + 1] − 1], sorted, unique. Empty (start.empty()) when unknown.
struct RowPattern {
    std::vector<int> start;  // m_all + 1 offsets (empty: pattern unknown)
    std::vector<int> cols;
    bool known() const { return !start.empty(); }
    int count(int r) const { return start[static_cast<std::size_t>(r) + 1] - start[static_cast<std::size_t>(r)]; }
    const int* row(int r) const { return cols.data() + start[static_cast<std::size_t>(r)]; }
};

struct ConstraintInfo {
    std::string name;
    ConstraintKind kind;
    int row;  // first row in the stacked arrays
    int dim;  // number of rows
};

// What an evaluation must produce (bit flags): the loop asks only for what a stage needs.
enum Need : unsigned {
    NEED_M = 1u << 0,
    NEED_H = 1u << 1,         // h = f_g − C qd (and f_passive)
    NEED_A = 1u << 2,
    NEED_GAMMA = 1u << 3,
    NEED_PHI = 1u << 4,       // position residual φ (gap for unilateral rows; 0 nonholonomic)
    NEED_VELOCITY = 1u << 5,  // A qd + φ_t
    NEED_B = 1u << 6,
    NEED_ENERGY = 1u << 7,    // kinetic + potential energy
    NEED_ALL = 0xffu,
    // f_g = h(t, q, 0) into Terms::f_g, from the same kinematics as the other terms (programs
    // with gravity_in_pass() only; not part of NEED_ALL)
    NEED_GRAVITY = 1u << 8,
};

// Outputs of one evaluation. Sized once by Program::make_terms(); evaluate() writes in place.
// Rows of A, gamma, phi, velocity of inactive constraints are left as they are (not read).
// Templated on the scalar: the programs that differentiate (evaluate_tangent) evaluate the
// same code on dual numbers (dual.hpp) into a TermsOf<Dual>.
template <class S>
struct TermsOf {
    using MatS = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    using VecS = Eigen::Matrix<S, Eigen::Dynamic, 1>;
    MatS M;          // n × n, symmetric
    VecS h;          // n
    VecS f_passive;  // n
    VecS f_g;        // n: h(t, q, 0) (NEED_GRAVITY)
    MatS B;          // n × k
    MatS A;          // m_all × n
    VecS gamma;      // m_all
    VecS phi;        // m_all
    VecS velocity;   // m_all
    S kinetic = S(0.0);
    S potential = S(0.0);

    void resize(int n, int k, int m_all) {
        M = MatS::Zero(n, n);
        h = VecS::Zero(n);
        f_passive = VecS::Zero(n);
        f_g = VecS::Zero(n);
        B = MatS::Zero(n, k);
        A = MatS::Zero(m_all, n);
        gamma = VecS::Zero(m_all);
        phi = VecS::Zero(m_all);
        velocity = VecS::Zero(m_all);
    }
};
using Terms = TermsOf<double>;

// One query of Program::residual_tangents: the dynamics residuals at a FIXED joint acceleration a
// (n) and fixed multiplier vectors λ_l (nlam rows of m_all, entries of inactive rows ignored),
//
//   r_dyn   = M(q) a − h(t, q, q̇) − f_p(t, q, q̇) − B(q) u     (n; u == nullptr: no B u)
//   r_lam,l = A(t, q)ᵀ λ_l                                    (n)
//   r_con   = A(t, q) a + γ(t, q, q̇)                          (m_all; active rows)
//
// and their exact directional derivatives along nd directions (dq_j, dq̇_j), rows j of dq and
// dqd (nd × n each, row-major). Outputs (row-major): r_dyn nd × n, r_lam nd × nlam × n, r_con
// nd × m_all (rows of inactive constraints: 0). The derivative pipeline (derivatives.cpp) needs
// only these products, never dM, dA themselves: Pinocchio's route (derivatives of inverse
// dynamics at the solution), on any program.
struct ResidualQuery {
    double t = 0.0;
    const double* q = nullptr;
    const double* qd = nullptr;
    const double* a = nullptr;
    const double* u = nullptr;
    int nlam = 0;
    const double* lam = nullptr;
    const std::uint8_t* active = nullptr;
    int nd = 0;
    const double* dq = nullptr;
    const double* dqd = nullptr;
    double* r_dyn = nullptr;
    double* r_lam = nullptr;
    double* r_con = nullptr;
};

// Preallocated scratch of one Program, one per thread (a Program itself is immutable and may be
// shared between threads).
struct Workspace {
    virtual ~Workspace() = default;
};

class Program {
  public:
    virtual ~Program() = default;

    int n() const { return n_; }
    int k() const { return k_; }
    int m_all() const { return m_all_; }
    const std::vector<ConstraintInfo>& constraints() const { return constraints_; }

    // Evaluate what `need` asks at (t, q, qd) for the active constraints (mask of length
    // constraints().size()). Returns Status::ok or the reason it could not (never NaN silently).
    virtual Status evaluate(double t, const double* q, const double* qd, const std::uint8_t* active,
                            unsigned need, Terms& out, Workspace& ws) const = 0;

    virtual std::unique_ptr<Workspace> make_workspace() const { return std::make_unique<Workspace>(); }

    Terms make_terms() const {
        Terms T;
        T.resize(n_, k_, m_all_);
        return T;
    }

    // Forward-mode derivatives (dual.hpp; docs/theory.md "Derivatives"): what `need` asks at
    // (t, q, qd) into `out` and its exact directional derivative along (dq, dqd) into
    // `tangent` (same layout, energies included). Programs not templated on the scalar return
    // Status::not_differentiable.
    virtual Status evaluate_tangent(double t, const double* q, const double* qd, const double* dq,
                                    const double* dqd, const std::uint8_t* active, unsigned need,
                                    Terms& out, Terms& tangent, Workspace& ws) const {
        (void)t, (void)q, (void)qd, (void)dq, (void)dqd, (void)active, (void)need, (void)out,
            (void)tangent, (void)ws;
        return Status::not_differentiable;
    }
    virtual bool differentiable() const { return false; }

    // The row pattern of A, fixed at load (programs that know it: PlanarProgram). Every entry of
    // A outside it is 0 at every state, and evaluate() writes only the pattern's entries of the
    // rows it writes: the other entries keep the zeros of make_terms(), so callers must not
    // write into a Terms' A themselves. Callers use it to copy, scan and check only those
    // entries (the loop's gathering of the active rows, the solver's row norms and profile).
    const RowPattern& a_pattern() const { return a_pattern_; }

    // The residual tangents of `rq` in multi-direction forward mode (dual.hpp's DualN: the
    // directions DUAL_WIDTH at a time). Programs without it return Status::not_differentiable
    // and the caller builds the same products from evaluate_tangent, one direction at a time.
    virtual Status residual_tangents(const ResidualQuery& rq, Workspace& ws) const {
        (void)rq, (void)ws;
        return Status::not_differentiable;
    }

    // Whether evaluate() answers NEED_GRAVITY (f_g = h(t, q, 0), bitwise the h of an evaluation
    // at q̇ = 0) from the kinematics of the same pass; otherwise a caller evaluates h at q̇ = 0.
    virtual bool gravity_in_pass() const { return false; }

    // True when M does not depend on q (planar absolute coordinates): the loop may validate and
    // factor it once.
    virtual bool constant_mass() const { return false; }

    // True when evaluate() asked without NEED_A / NEED_PHI skips their work and writes the other
    // terms all the same (planar programs): the loop then does not ask again for the A and φ it
    // keeps at an unchanged (t, q) (Loop::ev_ok). Otherwise it asks for the full terms.
    virtual bool constraint_terms_on_request() const { return false; }

    // Whether the Program may be evaluated from several threads at once (false for Python
    // callbacks, which hold the GIL).
    virtual bool thread_safe() const { return true; }

  protected:
    int n_ = 0;
    int k_ = 0;
    int m_all_ = 0;
    std::vector<ConstraintInfo> constraints_;
    RowPattern a_pattern_;
};

}  // namespace nonmin
