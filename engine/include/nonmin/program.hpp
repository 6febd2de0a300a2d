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
};

// Outputs of one evaluation. Sized once by Program::make_terms(); evaluate() writes in place.
// Rows of A, gamma, phi, velocity of inactive constraints are left as they are (not read).
struct Terms {
    Mat M;          // n × n, symmetric
    Vec h;          // n
    Vec f_passive;  // n
    Mat B;          // n × k
    Mat A;          // m_all × n
    Vec gamma;      // m_all
    Vec phi;        // m_all
    Vec velocity;   // m_all
    double kinetic = 0.0;
    double potential = 0.0;
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
        T.M = Mat::Zero(n_, n_);
        T.h = Vec::Zero(n_);
        T.f_passive = Vec::Zero(n_);
        T.B = Mat::Zero(n_, k_);
        T.A = Mat::Zero(m_all_, n_);
        T.gamma = Vec::Zero(m_all_);
        T.phi = Vec::Zero(m_all_);
        T.velocity = Vec::Zero(m_all_);
        return T;
    }

    // True when M does not depend on q (planar absolute coordinates): the loop may validate and
    // factor it once.
    virtual bool constant_mass() const { return false; }

    // Whether the Program may be evaluated from several threads at once (false for Python
    // callbacks, which hold the GIL).
    virtual bool thread_safe() const { return true; }

  protected:
    int n_ = 0;
    int k_ = 0;
    int m_all_ = 0;
    std::vector<ConstraintInfo> constraints_;
};

}  // namespace nonmin
