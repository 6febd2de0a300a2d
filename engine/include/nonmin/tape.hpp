// TapeProgram: a model given as closed-form expressions (SymPy models) compiled once to an
// expression tape — straight-line SSA code over double registers — that the engine evaluates
// with no Python and no compiler at run time (model layer).
//
// Registers: [t, q_0..q_{n−1}, qd_0..qd_{n−1}, p_0..p_{np−1}] (the inputs), then one register per
// instruction, in order; instruction i reads registers a, b (< its own) and the constant c.
// The Python compiler (src/nonmin/model/symbolic/_tape.py) walks the SymPy expressions after
// common-subexpression elimination (sympy.cse) and emits the tape and the output table:
// which register is which entry of M, h = f_g − C qd, f_passive, B, A, γ, φ, the velocity
// residual A qd + φ_t and the potential energy V. Entries not in the table are exactly zero.
// Each instruction carries the NEED_* flags of the outputs that depend on it, so an
// evaluation runs only what it was asked for.
#pragma once
#include <cstdint>
#include <vector>

#include "program.hpp"

namespace nonmin {

enum class TapeOp : int {
    constant = 0,  // c
    add = 1,       // a + b
    sub = 2,       // a − b
    mul = 3,       // a · b
    div = 4,       // a / b
    neg = 5,       // −a
    powi = 6,      // a^k, k = (int) c (any sign)
    pow = 7,       // a^b
    sqrt = 8,
    sin = 9,
    cos = 10,
    tan = 11,
    exp = 12,
    log = 13,
    asin = 14,
    acos = 15,
    atan = 16,
    atan2 = 17,  // atan2(a, b)
    sinh = 18,
    cosh = 19,
    tanh = 20,
    abs = 21,
    sign = 22,
    min = 23,
    max = 24,
    square = 25,  // a·a
    num_ops = 26
};

// Which array an output entry goes to.
enum class TapeTarget : int {
    M = 0, h = 1, f_passive = 2, B = 3, A = 4, gamma = 5, phi = 6, velocity = 7, V = 8
};

struct TapeDescription {
    int n = 0, k = 0, n_params = 0;
    std::vector<ConstraintInfo> constraints;  // rows in declaration order
    std::vector<int> op, a, b;                // one per instruction
    std::vector<double> c;
    std::vector<int> out_target, out_index, out_reg;  // output table: flat index in its array
};

// The tape pre-decoded for one set of NEED_* flags (built once per workspace and flag set, on
// first use): the instructions those flags need, in the tape's order, as runs of one op (no
// per-instruction flag test or dispatch), and the output table split by target.
struct TapePlan {
    unsigned need = 0;                          // the flags (need & 0xff)
    std::vector<int> run_op, run_end;           // runs [run_end[k−1], run_end[k]) of op run_op[k]
    std::vector<int> dst, a, b;                 // registers written and read
    std::vector<double> c;                      // powi's exponent
    // output entries of each target in table order: (flat index, register, constraint or −1)
    std::vector<int> out_start;                 // out_start[T] … out_start[T + 1] (TapeTarget T)
    std::vector<int> out_idx, out_reg, out_con;
};

struct TapeWorkspace : Workspace {
    std::vector<double> reg;
    std::vector<double> dreg;  // evaluate_tangent: the registers' directional derivatives
    std::vector<TapePlan> plans;
};

class TapeProgram final : public Program {
  public:
    // Validates the tape (operands before use, ops, output indices); throws EngineError.
    TapeProgram(TapeDescription desc, std::vector<double> params);

    Status evaluate(double t, const double* q, const double* qd, const std::uint8_t* active,
                    unsigned need, Terms& out, Workspace& ws) const override;
    // Forward mode over the tape: every register's derivative along (dq, dqd) by the chain rule
    // of its instruction, after the value pass (docs/linear.md).
    Status evaluate_tangent(double t, const double* q, const double* qd, const double* dq, const double* dqd,
                            const std::uint8_t* active, unsigned need, Terms& out, Terms& tangent,
                            Workspace& ws) const override;
    bool differentiable() const override { return true; }
    std::unique_ptr<Workspace> make_workspace() const override;

    int size() const { return static_cast<int>(d_.op.size()); }
    int n_inputs() const { return 1 + 2 * n_ + d_.n_params; }

  private:
    void schedule();  // reorder into runs of one op (dependencies kept)
    const TapePlan& plan(TapeWorkspace& w, unsigned need) const;

    TapeDescription d_;
    std::vector<double> params_;
    std::vector<std::uint8_t> need_;  // NEED_* flags of each instruction
    std::vector<int> out_row_constraint_;  // constraint of each output entry of A/γ/φ/velocity, else −1
};

}  // namespace nonmin
