// Many runs of the simulation loop in one call (nonmin.sim.simulate_batch, nonmin.sweep): k
// trajectories, each from its own initial state, with its own model (Program) and active set,
// its own step control (the loop of loop.hpp, unchanged: start() then run()), recorded on one
// common grid of output times. Threads take runs one at a time from a shared counter (runs of
// different cost balance), and each thread keeps one Loop per (program, active set) it meets:
// everything is allocated when a thread first meets a pair, nothing per run or per step (the
// sample buffers are reused after each run).
//
// Automatic contact runs through the engine's event layer (sim/events.hpp) exactly as in one run
// of simulate(): the contact guards of the active set at the start, each transition applied by
// contact_event() inside run(), then the loop resumed from the state after it (the bookkeeping
// the Python driver does between two engine calls: the Zeno count, the controller of the new
// active set). Compiled controllers (sim/control.hpp) are copied per thread and run
// (Controller::clone), one per active set met (ControllerSelect).
//
// A run that the loop does not finish alone — a numerical failure handed over, a step the event
// layer leaves to the Python driver, a Zeno accumulation, a callback error — ends with its
// outcome and message; nonmin.sim.simulate_batch then makes that run through simulate(), which
// raises (or records) what one run would.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "../program.hpp"
#include "loop.hpp"

namespace nonmin::sim {

// Which per-sample arrays a batch writes (the scalars t, energy, phi_norm, vel_norm, rank, cond,
// mu always).
enum RecordFlags : unsigned {
    REC_Q = 1u << 0,
    REC_QD = 1u << 1,
    REC_QDD = 1u << 2,
    REC_FC = 1u << 3,
    REC_U = 1u << 4,
};

struct BatchInput {
    int k = 0;                                 // runs
    std::vector<const Program*> programs;      // distinct models (all of one n, k, c)
    const std::int32_t* program_of = nullptr;  // k: index into programs
    double t0 = 0.0;
    const double* q0 = nullptr;                // k × n
    const double* qd0 = nullptr;               // k × n
    const std::uint8_t* active = nullptr;      // k × c (one mask per run)
    Options opt;                               // shared settings (opt.t1 the end time)
    std::vector<double> t_out;                 // output grid (N times in [t0, t1])
    unsigned record = REC_Q | REC_QD;
    int threads = 0;                           // ≤ 0: hardware concurrency
    // automatic contact (simulate's contact=True with unilateral constraints): Newton's e per
    // constraint, the impact velocity threshold, the Zeno limit (more than zeno_max events
    // within zeno_window ends the run: `zeno` outcome, made again by simulate())
    bool contact = false;
    std::vector<double> restitution;
    double v_thresh = 1e-6;
    int zeno_max = 100;
    double zeno_window = 1e-3;
    // compiled controllers: the prototype of (program ctrl_program[j], active set ctrl_mask[j]),
    // cloned per thread and run; empty: no controller
    std::vector<const Controller*> ctrl_protos;
    std::vector<int> ctrl_program;
    std::vector<std::vector<std::uint8_t>> ctrl_mask;
};

// Per-run results; sample arrays are (k × N × width), row-major, NaN where not reached.
struct BatchOutput {
    double* q = nullptr;    // k × N × n   (REC_Q)
    double* qd = nullptr;   // k × N × n   (REC_QD)
    double* qdd = nullptr;  // k × N × n   (REC_QDD)
    double* f_c = nullptr;  // k × N × n   (REC_FC)
    double* u = nullptr;    // k × N × nu  (REC_U)
    double* energy = nullptr, *phi_norm = nullptr, *vel_norm = nullptr, *cond = nullptr,
           *mu = nullptr, *work = nullptr;  // k × N (work: W of controllers and applied forces)
    std::int64_t* rank = nullptr;  // k × N
    std::uint8_t* active = nullptr;  // k × N × c: the active set of each sample (contact runs)
    std::int32_t* outcome = nullptr;  // k: Outcome (done = the run reached t1)
    std::int64_t* samples = nullptr;  // k: samples written
    std::int64_t* n_steps = nullptr, *n_rhs = nullptr, *n_rejected = nullptr;  // k
    double* t_end = nullptr;          // k
    double* y_end = nullptr;          // k × 2n
    std::vector<std::string>* messages = nullptr;  // k
    std::vector<std::vector<EventInfo>>* events = nullptr;  // k: the transitions applied (contact)
};

// Run the batch; returns the number of runs whose outcome is not `done`.
int simulate_batch(const BatchInput& in, const BatchOutput& out);

}  // namespace nonmin::sim
