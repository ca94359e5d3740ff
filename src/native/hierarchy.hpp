// qpcoord native engine: dense exact strict-hierarchy (lexicographic) least squares.
//
// Same problem and semantics as qpcoord.core.methods.hierarchical (the Python engine):
//   bounds lb <= x <= ub and the hard rows always hold; level k minimises
//   ||Ae_k x - be_k||^2 + sum_i sw_i^2 dist(C_i x, [lo_i, hi_i])^2 over the optimal set of the
//   levels above; then the minimum-norm x over the last optimal set.
//
// Algorithm: variable elimination. x = xbar + Z z with Z an orthonormal basis of the freedom
// left. Per level: the damped closed form of the projected equalities (min-norm: a pivoted QR
// when it reveals the rank with a clear gap and no damping applies, else the SVD); if it
// meets the level's inequalities, the inherited rows and the bounds it is the optimum.
// Otherwise an exact primal active-set least-squares solve in y = (z, w), w the slacks of the
// level's inequality rows, from a feasible start (z = 0, w = the rows' current violation),
// warm-started from the previous call's working set of that level. The optimum is frozen:
// Z <- Z null([Vt_rank; violated rows]), satisfied rows are inherited (opened to their value).
//
// docs/engine.md describes the design: the stages, the warm start, the caches and the rank
// decisions, and the invariants each relies on.
#pragma once

#include <Eigen/Dense>
#include <array>
#include <chrono>
#include <cstdint>
#include <limits>
#include <vector>

#include "dense.hpp"
#include "keyed_cache.hpp"

namespace qpcoord {

/// The extension's interface version (qpcoord/core/native.py refuses a module of another):
/// raised whenever a binding changes.
inline constexpr int kAbiVersion = 17;

/// The SVD of the closed forms (used when the QR closed form does not apply: damping active
/// or a rank the QR cannot settle): Eigen's one-sided Jacobi SVD with its QR preconditioner,
/// kept per stage. Not BDCSVD: Eigen 3.4's BDCSVD::compute allocates on every call (a local
/// JacobiSVD below 16 columns, a scaled copy and a bidiagonalisation above: 4-80 heap
/// allocations per call, counted by tools/count_allocations.hpp), whereas JacobiSVD::compute
/// reuses its members when the size repeats (no allocation after the first call of a size).
using Svd = Eigen::JacobiSVD<Mat>;

template <typename T>
using CRef = Eigen::Ref<const T, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
template <typename T>
using MRef = Eigen::Ref<T, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;

/// Status codes of Hierarchy::solve (qpcoord/core/native.py turns them into exceptions).
enum Status : int {
  kOk = 0,
  kInfeasibleEq = 1,    ///< inconsistent hard equalities (detail[0]: residual norm)
  kInfeasibleHard = 2,  ///< hard inequalities and bounds inconsistent (detail[1]: violation)
  kNonFinite = 3,       ///< a non-finite number in the result
  kNotConverged = 4,    ///< an active-set solve hit its iteration limit (detail[2]: stage)
  kBadInput = 5,        ///< wrong shapes or non-finite data
  kTimeLimit = 6,       ///< the time limit passed during an active-set solve (detail[2]: stage)
  kCheckFailed = 7,     ///< the final x fails the check of the bounds or hard rows
                        ///< (detail[3]: 1 bounds, 2 hard equalities, 3 hard inequalities;
                        ///< detail[4]: the offending index or residual norm)
};

/// min 1/2 ||Q y - c||^2  s.t.  lo <= G y <= hi  (rows of G normalised), with row ids.
struct LsqProblem {
  Mat Q;
  Vec c;
  Mat G;
  Vec lo, hi;
  std::vector<int> id;  ///< global id of each row of G (warm start)
  int rows = 0;         ///< rows of G in use
  int cols = 0;
  int qrows = 0;
  /// |r0|^2 of objective rows dropped by an orthogonal compression (constant in y: a tall
  /// level's M and e replaced by R and (Qm^T e)(0:r) of M's QR): the tolerances that are
  /// relative to the objective's value or |c| count it, so they do not change
  double dropped2 = 0.0;
  /// A level's slack structure (0 slacks: none, or not this layout): y = (z, w), z the first
  /// `zcols` columns; slack j (column zcols + j) has one objective row, slack_q0 + j (the last
  /// `slacks` rows of Q, sw_j on its column only), and one row of G, slack_g0 + j (the level
  /// row it relaxes: the last `slacks` rows of G); no other row of Q or G touches it.
  int zcols = 0;
  int slacks = 0;
  int slack_q0 = 0;
  int slack_g0 = 0;
  /// |c| of the uncompressed objective
  double c_norm() const { return std::sqrt(c.head(qrows).squaredNorm() + dropped2); }
  void resize(int max_qrows, int max_grows, int max_cols);
  void start(int qrows_, int cols_);
  /// Append row g (scaled by 1/||g||) with bounds [l, u]; skips rows that cannot bind (both
  /// sides infinite, or ||g|| at most floor * ref_norm: constant). Returns the row's norm, or
  /// 0 when it was skipped.
  double add_row(const Eigen::Ref<const Vec>& g, double l, double u, int gid, double ref_norm,
                 double floor = 1e-12);
};

/// What a user may tune in a Hierarchy (Hierarchy::settings; bound to Python).
struct Settings {
  /// Multiplier sign tolerance of the active set, relative to the largest entry of the
  /// gradient (dimensionless; the Python engine's KKT_TOL). Default 1e-9.
  double kkt_tol = 1e-9;
  /// A level row whose violation at the level's optimum exceeds this, relative to the
  /// row's scale (max(|lo|, |hi|, |C_i| |x|)), is frozen violated, else inherited
  /// (dimensionless; the Python engine's VIOLATION_TOL). Default 1e-6.
  double violation_tol = 1e-6;
  /// Iteration cap of each active-set solve: max_iter_factor (rows + columns) + 10
  /// iterations (count per row and column of the stage's problem). Default 6.
  int max_iter_factor = 6;
  /// Wall-clock limit of one solve, in seconds (inf: none); the smaller of it and the
  /// solve's time_left applies. Default inf.
  double time_limit = std::numeric_limits<double>::infinity();
};

/// Counters of one solve (Hierarchy::stats(); NativeHierarchy.counters in Python): how
/// often each path and cache was taken. They describe the work, never the answer.
struct Stats {
  int downdates = 0;             ///< rows that left a working set by a QR downdate
  int slack_steps = 0;           ///< least-squares steps by the slack structure (slack_step)
  int least_distance_steps = 0;  ///< minimum-norm steps as a least-distance problem
  int k_qr_reuses = 0;           ///< least-squares steps that reused K's factorisation
  int batch_rows = 0;            ///< rows added at once to a working set at a degenerate point
  int reduced_trials = 0;        ///< warm trials of a level solved in z alone
  int rz_factors = 0;            ///< RZ factorisations of [R11 R12]
  int qr_closed_forms = 0;       ///< levels whose closed form came from the QR of M (no SVD)
  int small_rinvs = 0;           ///< QR closed forms bounded by back substitution
  int zero_tail_compressions = 0;  ///< levels compressed past an exactly zero trailing block
  int identity_products = 0;     ///< products with an identity Z skipped
  int null_space_freezes = 0;    ///< freezes onto null([R11 R12]) of the closed form's QR
  int full_rank_freezes = 0;     ///< levels that left no freedom (no freeze computed)
  int wide_freezes = 0;          ///< freezes by a wide M^T's own reflectors
  int dependent_drops = 0;       ///< levels whose rows lost directions dependent on frozen ones
  int gram_screens = 0;          ///< dependence QRs skipped on a Cholesky proof
  int freeze_memo_hits = 0;      ///< freezes restored from the freeze cache
  int closed_form_memo_hits = 0;  ///< closed forms whose factorisation was reused
  int trial_memo_hits = 0;       ///< warm trials whose factorisations were reused
  int bound_rows_memo_hits = 0;  ///< stages whose bound rows were copied from the cache
  int wy_applications = 0;       ///< changes of Z by the compact WY form (FMA builds)
  int pruned_working_sets = 0;   ///< levels whose set was stored without its far rows
  int zero_objective_hits = 0;   ///< warm trials accepted at a zero objective (any multipliers)
  int range_trials = 0;          ///< warm trials stepped through the closed form's R (no K)
};

/// The strict-hierarchy solver of one stack structure (sizes fixed at construction).
class Hierarchy {
 public:
  /// n variables; block 0 = hard constraints, block k+1 = level k; meq/min = rows per block.
  Hierarchy(int n, std::vector<int> meq, std::vector<int> min, bool has_bounds, double damping);

  /// Solve with the current numbers. Rows are stacked block after block (hard first).
  /// stats: (levels + 2) x 3 doubles, per stage (hard, levels..., min-norm):
  ///   active-set iterations, warm-start hit (0/1), closed form accepted (0/1).
  /// detail: 8 doubles (hard eq residual, hard violation, failing stage, check kind, check
  /// index or residual, worst level consistency deviation (relative), its level, levels
  /// whose stored working set missed and seeded the active set's start).
  /// res_out: each level's value at x (norm of the weighted equality residual and
  /// inequality violation, as CompiledLevel.residual). time_left: seconds (inf: none),
  /// checked at every active-set iteration.
  int solve(const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C, const CRef<Vec>& lo,
            const CRef<Vec>& hi, const CRef<Vec>& sw, const CRef<Vec>& lb, const CRef<Vec>& ub,
            bool warm, double time_left, MRef<Vec> x_out, MRef<Vec> res_out, MRef<Mat> stats,
            MRef<Vec> detail);

  int n() const { return n_; }
  int num_levels() const { return static_cast<int>(meq_.size()) - 1; }
  double damping() const { return damping_; }

  /// What a user may tune; the defaults are the Python engine's tolerances.
  Settings settings;
  /// The counters of the last call.
  const Stats& stats() const { return stats_; }
  /// Forget every cached factorisation, product and freeze (the next call computes them
  /// all, as when its matrices changed); the stored working sets stay. The next call's x is
  /// the same bit for bit: a cache only ever returns what computing gives.
  void invalidate_caches();

 private:
  struct Working {  ///< a stage's final working set: (row id, side)
    std::vector<int> id;
    std::vector<int8_t> side;
    /// a set was stored (it may hold no one-sided row: the stage's optimum has only its
    /// equality rows active, and is still a warm start)
    bool stored = false;
    /// stored after store_level_working_set's verification, pruned or whole (a later hit of
    /// it is not verified again: the set changes only after a miss)
    bool verified = false;
  };

  int hard_phase(const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                 const CRef<Vec>& lo, const CRef<Vec>& hi, MRef<Mat> stats, MRef<Vec> detail,
                 bool warm);
  int level(int k, const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
            const CRef<Vec>& lo, const CRef<Vec>& hi, const CRef<Vec>& sw, MRef<Mat> stats,
            bool warm);
  int min_norm(MRef<Mat> stats, bool warm);
  /// solve's arguments have the sizes of this structure and no NaN or wrong-sided infinity:
  /// kOk, else kBadInput.
  int check_input(const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                  const CRef<Vec>& lo, const CRef<Vec>& hi, const CRef<Vec>& sw,
                  const CRef<Vec>& lb, const CRef<Vec>& ub, const MRef<Vec>& x_out,
                  const MRef<Vec>& res_out, const MRef<Mat>& stats,
                  const MRef<Vec>& detail) const;
  /// A call's start: the caches' buffers at the second call, the counters reset, the
  /// deadline set.
  void start_call(double time_left);
  /// The end check of x (finite, bounds, hard rows: check_point) and each level's value at
  /// x with its worst deviation from the value it was frozen with (detail 5, 6).
  int certify(const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
              const CRef<Vec>& lo, const CRef<Vec>& hi, const CRef<Vec>& sw, MRef<Vec> x_out,
              MRef<Vec> res_out, MRef<Vec> detail);

  /// A level's rows in the stacked arrays (references valid for one call) and where they are.
  struct LevelRows {
    const CRef<Mat>& Aeq;
    const CRef<Vec>& beq;
    const CRef<Mat>& C;
    const CRef<Vec>& lo;
    const CRef<Vec>& hi;
    const CRef<Vec>& sw;
    int stage, me, mi, e0, i0;  ///< its stage; equality and inequality rows, their first
  };
  /// What a level's closed form found (its step x + Z dz is in xc_).
  struct LevelForm {
    int rank = 0;         ///< numerical rank of M (independent of the frozen rows)
    double tau = 0.0;     ///< the damping threshold (singular values under it are damped)
    double scale = 0.0;   ///< |A|_F of the level's equalities (>= s_0 of M)
    bool by_qr = false;   ///< from the pivoted QR of M (no damping applies), no SVD
  };
  /// The closed form: M = A Z (unless same_m: the closed-form cache's), the minimum-norm
  /// damped least-squares step of M dz = e by the QR of M when it settles the rank, else the
  /// SVD; xc_ = x + Z dz.
  LevelForm level_closed_form(const LevelRows& d, bool same_m);
  /// True when xc_ meets the bounds, the inherited rows and the level's rows: x moves there,
  /// the level's rows are inherited and its optimal set frozen.
  bool accept_closed_form(const LevelRows& d, const LevelForm& form);
  /// The level's least squares in y = (z, w) into P_: its objective (M, or the R of its QR,
  /// the damping rows), the inherited rows, the bounds and its moving rows with their slacks
  /// (mov_; CZl_ = C Z). Returns the number of moving rows. With `only`: of the inherited
  /// rows and bounds only those of the stored set `only` and those fixed (lo = hi), in P's
  /// order (the level's own rows all): the rows a warm trial of `only` reads (light_trial).
  int level_problem(const LevelRows& d, const LevelForm& form, const Working* only = nullptr);
  /// The warm trial of a well-conditioned level on the objective, its own rows and its stored
  /// set's other rows alone (level_problem with only): a hit when the trial hits there and
  /// its point meets the rows left out (left_out_rows_feasible), as the trial on the whole
  /// problem decides; y (z, w) and W_ (on that P) set as try_working_set leaves them, mov_,
  /// CZl_ and rows_pivot_ as level_problem, and the set stored as store_level_working_set
  /// stores it after a hit (a set it prunes: kHitStore). Not tried when the level is
  /// ill-conditioned (its hit is finished by the active set) or when no row was left out
  /// (the whole trial follows, on P_ as built: a second trial of the same rows would be the
  /// trial cache's hit within one call).
  enum class Light : int8_t {
    kHit,       ///< a hit, the set stored: the level's optimum
    kHitStore,  ///< a hit whose set store_level_working_set prunes: on the whole problem
    kWhole,     ///< not tried (ill-conditioned, or nothing left out): P_ is the whole problem
    kRebuild,   ///< a miss, or not tried: the whole problem is to be built
  };
  Light light_trial(const LevelRows& d, const LevelForm& form, Working& ws, Eigen::Ref<Vec> y);
  /// z meets the inherited rows and bounds level_problem(only = ws) left out, to
  /// try_working_set's tolerance on each row scaled to unit norm; rows that cannot bind (the
  /// ones add_row skips) are not checked.
  bool left_out_rows_feasible(const Working& ws, const Eigen::Ref<const Vec>& z);
  /// The level is ill-conditioned or damped: its active set is finished to rounding.
  bool ill_conditioned(const LevelRows& d, const LevelForm& form) const;
  /// Marks in viol_ the moving rows the new x leaves violated (relative to their scale);
  /// returns their number.
  int violated_rows(const LevelRows& d);
  /// Inherits the level's satisfied rows and freezes its optimal set (Z <- Z null(F)).
  void freeze_level(const LevelRows& d, const LevelForm& form, int nviol);

  /// The closed form of a level's projected equalities M dz = e by a pivoted QR of M (tall)
  /// or M^T (wide), when the QR reveals M's numerical rank with a clear gap: the trailing
  /// block R22 below the rank tolerance `tol` (so sigma_{rank+1}(M) <= |R22|_F < tol) and
  /// 1/|R11^-1|_F <= sigma_rank(M) above kQrMargin x `floor` (the damping threshold and the
  /// rank tolerance). Then the SVD's numerical rank is this rank, no singular value is
  /// damped, and the SVD's truncated closed form is the minimum-norm least-squares solution
  /// of the complete orthogonal decomposition (R22 dropped), computed here. Returns the rank
  /// or -1: use the SVD. same_m: M is bit for bit the one in the stage's Ms_ at its last
  /// call (the closed-form cache reuses that call's factorisation, or its failure).
  int qr_closed_form(const Eigen::Ref<const Mat>& M, const Eigen::Ref<const Vec>& e, double tol,
                     double floor, bool same_m, Eigen::Ref<Vec> dz);
  /// qr_closed_form's factorisations (cf_: mqr, and tqr or trz when M is rank-deficient):
  /// the rank, or -1 (no clear gap: the SVD).
  int qr_factor(const Eigen::Ref<const Mat>& M, double tol, double floor);
  /// The closed-form cache's lookup at level stage's entry: true when its rows A and C and
  /// Z are bit for bit those the stage's M (Ms_) and its factorisations were computed from.
  /// The rows are compared first, Z only once they repeat (a changed Jacobian differs at its
  /// first entries: then Z is not recorded). False on the first call and below a freeze
  /// computed in this call (memo_gate).
  bool closed_form_lookup(int stage, const CRef<Mat>& Aeq, int e0, int me, const CRef<Mat>& C,
                          int i0, int mi);
  /// M = A Z was computed from the inputs closed_form_lookup gave: the entry holds it (when
  /// the lookup gave them all).
  void closed_form_store(int stage);
  /// An orthonormal basis of M's row space (r x rank) into out: V_rank of the SVD, or from
  /// the QR of qr_closed_form (rank-deficient tall M: the QR of [R11 R12]^T in the stage's tqr).
  void row_space_basis(const Svd& svd, bool by_qr, int rank,
                       Eigen::Ref<Mat, 0, Eigen::OuterStride<>> out);
  /// x in the bounds and the inherited rows' boxes (the rows by one product Cin x).
  bool feasible(const Eigen::Ref<const Vec>& x);
  void inherit(const CRef<Mat>& C, const CRef<Vec>& lo, const CRef<Vec>& hi, int row0, int m,
               const std::vector<char>* skip);
  /// |Cin_.row(i)| (the scale below which inherited row i's projection cannot bind),
  /// computed on first use in a call and kept: every level's add_inherited_rows reads it
  double cin_norm(int i);
  /// The inherited rows as rows of P (all, or with only: those in the set or fixed).
  void add_inherited_rows(LsqProblem& P, const Working* only = nullptr);
  /// The bounds as rows of P (Z's rows scaled to unit norm; the bound-rows cache: copied from
  /// the stage's last call when its Z repeats; with only: those in the set or fixed, no cache).
  void add_bound_rows(LsqProblem& P, int stage, const Working* only = nullptr);
  /// The bound-rows cache's value: a stage's bound rows as add_bound_rows wrote them (every
  /// variable's row kept); its key: r and the Z (n x r) they were projected from.
  struct BoundRows {
    Mat G;    ///< the scaled rows (n x r)
    Vec nrm;  ///< each row's norm before scaling (the bounds are scaled by it)
  };
  using BoundRowsCache = KeyedCache<BoundRows, Stats, &Stats::bound_rows_memo_hits>;
  std::vector<BoundRowsCache> bound_rows_;  ///< per stage (levels and the minimum-norm step)
  /// Apply a change of Z (Z <- Z Qf of qr, its first rank columns dropped) to the carried
  /// projection of the inherited rows; call before r_ changes.
  void carry_z(PivotedQR& qr, int rank);
  /// Z <- Z null(F) with F^T the r x f matrix already in fqr_ (rank relative to scale).
  void freeze(double scale);
  /// Z <- Z P N after qr_closed_form found a tall M of rank < r (N from the stage's RZ of
  /// [R11 R12]); the carried projection Cin Z follows by the same product.
  void freeze_null_space(int rank);
  /// The rank of a level's M without directions dependent on the frozen rows to within the
  /// movable tolerance (robust: see hierarchy.cpp).
  int independent_rank(const Svd& svd, const CRef<Mat>& Aeq, int e0, int me, int rank,
                       double scale);
  /// Rows of R (a level's moving rows' projections) without the directions in which they
  /// are dependent to within the movable tolerance (robust: see hierarchy.cpp). Returns the
  /// last pivot the rows keep (scaled by their norms), or 1 when every pivot is proven at
  /// least kIllConditioned.
  double drop_dependent_directions(Eigen::Ref<Mat> R, const std::vector<int>& rows,
                                   const Eigen::Ref<const Vec>& norms);
  /// True when the r x m matrix T proves every pivot of its column-pivoted QR at least
  /// pivot_floor (see hierarchy.cpp).
  bool independent_by_gram(const Eigen::Ref<const Mat>& T, double pivot_floor);
  /// Z <- Z Qf(:, rank:) after a wide M's QR in the stage's mqr (M^T = Qf R: null(M) is spanned by
  /// Qf's last r - rank columns); the carried projection follows (carry_z).
  void freeze_wide(int rank);
  /// The freeze a level makes (the freeze cache's key: the same function of the same inputs
  /// whether the level ended by its closed form or its active set): Z <- Z Qf by a wide M^T's
  /// reflectors, Z <- Z P N from the QR of [R11 R12], or the QR of F^T = [B, violated rows].
  enum class FreezeKind : int8_t { kWide, kNullSpace, kGeneral };
  /// The freeze cache: true when the stage's stored freeze had these inputs (the level's
  /// entry held: rows and Z on entry the same; kind, rank, Cin Z now, the violated rows when
  /// with_viol): Z_, r_, z_identity_, kz_ and Cin Z are then set to its outputs. Else false;
  /// when the rows repeat the inputs are recorded (the outputs by freeze_computed).
  bool freeze_lookup(int stage, FreezeKind kind, int rank, int mi, bool with_viol);
  /// A freeze was computed: its outputs stored with freeze_lookup's inputs (when it recorded
  /// them); the lower levels look nothing up in this call (their Z differs from the previous
  /// call's: a comparison and copies for nothing, the IK's case).
  void freeze_computed(int stage);
  /// the caches on (their buffers allocated), and no freeze of this call computed so far (Z
  /// may repeat the last call's)
  bool memo_gate() const {
    return per_stage_ && z_repeats_;
  }
  bool z_repeats_ = false;
  bool entry_rows_same_ = false;  ///< closed_form_lookup of the level being solved: A, C repeat
  void snap(Vec& x) const;

  /// Exact primal active set from the feasible y; W: 0 free, -1 lower, +1 upper, 2 equality.
  bool active_set(const LsqProblem& P, Eigen::Ref<Vec> y, std::vector<int8_t>& W, int& iters);
  /// At a degenerate point: after the row blocking the step at length zero entered W, the
  /// other rows outside W (but `dropped`) that block it at length zero (active_set's ratio
  /// test on its products gp_, gy_) enter too; their QR appended while `current` (else
  /// current = false).
  void add_zero_blockers(const LsqProblem& P, std::vector<int8_t>& W,
                         int dropped, double smax, double yscale, bool& current);
  /// Map a stored working set onto P's rows (into W), factor it and write the minimum-norm
  /// least-squares point on it into xc_; returns the number of stored rows matched (0: none,
  /// or an infinite bound); *consistent: the point meets the set's rows.
  int stored_set_point(const LsqProblem& P, const Working& ws, std::vector<int8_t>& W,
                       bool* consistent);
  /// stored_set_point's factorisations for a level with range_trial_ (from the trial cache
  /// where it holds them): the working rows' QR (wqr) and, when they have full rank, the QR
  /// of B = R^-T P^T G_w^T (k x kw: kw triangular solves) in bqr; ts_->range: B has full
  /// column rank. No Q Qf and no K. Returns true when computed (not restored).
  bool factor_range_trial(const LsqProblem& P, const std::vector<int8_t>& W);
  /// The step from y (on the working rows) to the optimum on them, through R alone:
  /// y += d, d = -P R^-1 (I - P_B) (Q y - c), P_B the projector onto the range of B (where
  /// the general trial forms Q Qf and factorises the k x (k - kw) K = Q N).
  void range_step(const LsqProblem& P, Eigen::Ref<Vec> y);
  /// Map a stored working set onto P's rows (into W: equality rows 2, stored rows their
  /// side); returns the number of stored rows matched.
  int map_working_set(const LsqProblem& P, const Working& ws, std::vector<int8_t>& W);
  /// The minimum-norm point on the working rows of factor_trial's factorisation of P (wqr,
  /// widx_): G_w y = t, t the rows' active bounds, into y (P.cols entries); *consistent: G_w y
  /// = t holds to 1e-10 max(1, |t|). False (y unset) when an active bound is infinite.
  /// The gradient g = Q^T (Q y - c) of P at y into gvec_, and the tolerance below which a
  /// multiplier counts as negative: settings.kkt_tol of max |g| (none in the exact finish) plus the
  /// rounding of g itself, qn being the scale of Q (multipliers_ok, reduced_multipliers_ok).
  double sign_tolerance(const LsqProblem& P, const Eigen::Ref<const Vec>& y, double qn);
  bool working_set_point(const LsqProblem& P, const std::vector<int8_t>& W, Eigen::Ref<Vec> y,
                         bool* consistent);
  /// stored_set_point of a level whose last mv rows of P have one slack column each (column
  /// P.cols - mv + j, objective row P.qrows - mv + j): the least squares in z alone (Pr_),
  /// each working slack row's slack eliminated (w = (g_z z - t) / s: its objective term a row
  /// in z), the others' slack 0, the rows without slack the working rows of Pr_'s QR (wqr);
  /// the point (z, w) into xc_. -1: not reducible (a working slack row without weight).
  int reduced_set_point(const LsqProblem& P, int mv, const Working& ws, std::vector<int8_t>& W,
                        bool* consistent);
  /// multipliers_ok after reduced_set_point (no drop): a working slack row's multiplier from
  /// its slack column, the others' from the QR of the working rows without slack.
  bool reduced_multipliers_ok(const LsqProblem& P, int mv, const Eigen::Ref<const Vec>& y,
                              const std::vector<int8_t>& W);
  /// Try a stored working set: solve on it, check feasibility and multiplier signs. *found:
  /// the stored rows matched (its point stays in xc_ for seed_working_set on a miss).
  bool try_working_set(const LsqProblem& P, const Working& ws, Eigen::Ref<Vec> y,
                       std::vector<int8_t>& W, int* found);
  void store_working_set(const LsqProblem& P, const std::vector<int8_t>& W, Working& ws);
  /// store_level_working_set's test after storing W_: the working rows of P without slack
  /// whose bound is away from the level's start (Wp_: W_ without them) exist and y has a
  /// zero objective: the set is to be pruned.
  bool prunes(const LsqProblem& P, const Eigen::Ref<const Vec>& y, int level_rows);
  /// A level's working set W_ at its optimum y (hit: y is the warm trial's of ws, no exact
  /// finish moved it), stored for the next call's trial. When the level's objective is zero
  /// there (to rounding: every row of the level met), every multiplier is zero and a working
  /// row matters only for its point's feasibility: the rows without slack (bounds, inherited
  /// rows) whose bound is away from the level's start (|t| > violation_tol max(1, |y|)) are
  /// dropped, the rows the rest's point violates added, up to kPruneRounds warm trials
  /// (try_working_set); the first that hits is stored, else the whole set. Either way the
  /// stored set is not verified again while its trials hit (a hit of it keeps it).
  /// level_rows: the last rows of P, the level's own (one slack column each).
  void store_level_working_set(const LsqProblem& P, const Eigen::Ref<const Vec>& y,
                               int level_rows, bool hit, Working& ws);
  /// The objective of P at y is zero to the rounding of Q y - c (a feasible y is optimal).
  bool zero_objective(const LsqProblem& P, const Eigen::Ref<const Vec>& y);
  /// A stage's warm start and active set, the one rule of the hard phase, the levels and the
  /// minimum-norm step: with warm, the stored working set ws is tried first (hit: its point
  /// is the optimum, into y and W_); on a miss whose stored rows matched, the active set
  /// starts from the stored set made feasible (seed_working_set; the first hard_rows rows of
  /// P have no slack), else cold: W_ holds the equality rows only and cold_start(y) sets the
  /// starting point. slack_rows: the level's own rows with one slack column each (the
  /// reduced trial), 0 otherwise. Returns kOk, or kTimeLimit / kNotConverged.
  template <typename ColdStart>
  int warm_started_active_set(const LsqProblem& P, const Working& ws, bool warm, int hard_rows,
                              int slack_rows, Eigen::Ref<Vec> y, ColdStart cold_start,
                              int& iters, bool& hit);
  /// After a miss of a level's stored working set: a feasible start near its point. The
  /// stored set's point (its rows held, the least squares on them) gives z_p; the ratio test
  /// from z = 0 (feasible) towards z_p on the rows without slack (the first `hard_rows` rows
  /// of P: inherited rows and bounds) gives z = alpha z_p; each level row's slack is its
  /// violation at z (the cheapest feasible slack); the working set is the stored rows still
  /// tight at that point plus the blocking row (alpha = 0: the cold start's point with the
  /// stored rows tight there). Call after a try_working_set of ws that matched rows (its
  /// point and W's mapping are reused, not recomputed).
  bool seed_working_set(const LsqProblem& P, const Working& ws, int hard_rows, int zcols,
                        Eigen::Ref<Vec> y, std::vector<int8_t>& W);
  /// Factorise the working set W: pivoted QR of G_w^T (wqr), its rows in widx_, and
  /// Qt = Q Qf (the objective in the QR's basis: its last columns span null(G_w)).
  void factor_working(const LsqProblem& P, const std::vector<int8_t>& W);
  /// The working set's rows of W in widx_ and the pivoted QR of their G_w^T in wqr (the
  /// common part of factor_working and factor_trial).
  void factor_rows(const LsqProblem& P, const std::vector<int8_t>& W);
  /// Qt = Q Qf for the working set's current QR (all its transforms so far).
  void form_qt(const LsqProblem& P);
  /// factor_working for a warm trial: the same QR of G_w^T, but of Q Qf only
  /// the columns rank.. that ls_step reads (none when G_w pins y); the active set's updates
  /// need all of Q Qf and start from factor_working
  void factor_trial(const LsqProblem& P, const std::vector<int8_t>& W);
  /// factor_trial's factorisations, computed (the trial cache missed).
  void factor_trial_computed(const LsqProblem& P, const std::vector<int8_t>& W);
  /// The trial cache: true when the stage's trial state holds the factorisations of P's
  /// working rows of W and its objective, bit for bit (then widx_ and the flags are set as
  /// factor_trial leaves them); else the inputs are recorded (factor_trial stores).
  bool trial_lookup(const LsqProblem& P, const std::vector<int8_t>& W);
  /// The minimum-residual step in null(G_w) from y (factor_working first); res_ = Q y - c.
  void ls_step(const LsqProblem& P, const Eigen::Ref<const Vec>& y, Eigen::Ref<Vec> step);
  /// Form the projected objective K = Q N of the working set's QR and factorise it for
  /// ls_step (k_mode_, k_rank_; sets k_valid_); false when K is rounding noise (zero step).
  bool factor_k(const LsqProblem& P);
  /// The step of ls_step by the slack structure of P: the minimum-norm step with
  /// G_w step = 0 and Q step = -res_ when the system, its slacks eliminated, has full row
  /// rank (then consistent: the same step as the projected least squares); false: take the
  /// general path.
  bool slack_step(const LsqProblem& P, Eigen::Ref<Vec> step);
  /// Multiplier signs on W (factor_working of this W first); else the row to drop in *drop
  /// (the most negative multiplier, or with bland the lowest index); rows flagged in keep are
  /// not dropped.
  bool multipliers_ok(const LsqProblem& P, const Eigen::Ref<const Vec>& y,
                      const std::vector<int8_t>& W, int* drop, const std::vector<char>* keep,
                      bool bland);

  int n_;
  std::vector<int> meq_, min_, eq0_, in0_;
  bool has_bounds_;
  double damping_;
  int capacity_;

  // state of one solve
  Vec x_;
  Mat Z_;  ///< n x r orthonormal basis of the remaining freedom
  int r_ = 0;
  Mat Cin_;  ///< inherited rows (capacity x n)
  Mat CinZ_;  ///< the inherited rows projected, Cin Z (capacity x n; rows 0..kz_ current)
  int kz_ = 0;  ///< inherited rows whose projection in CinZ_ is carried (carry_z)
  Vec cinx_;  ///< workspace: Cin x (add_inherited_rows, feasible; read where it is formed)
  int left_out_ = 0;  ///< rows of the last level_problem left out by its `only`
  Vec lin_, uin_;
  /// |Cin_.row(i)| once computed, else -1 (cin_norm)
  Vec cin_norm_;
  std::vector<int> inid_;
  int k_ = 0;
  Vec lb_, ub_;

  double level_value(int k, const CRef<Mat>& Aeq, const CRef<Vec>& beq, const CRef<Mat>& C,
                     const CRef<Vec>& lo, const CRef<Vec>& hi, const CRef<Vec>& sw,
                     const Vec& x, double* scale = nullptr) const;
  bool out_of_time() const {
    return has_deadline_ && std::chrono::steady_clock::now() >= deadline_;
  }

  bool has_deadline_ = false;
  bool timed_out_ = false;
  std::chrono::steady_clock::time_point deadline_;
  Vec frozen_value_;  ///< each level's value when it was frozen
  int seeded_ = 0;    ///< stages of this call started from a seeded working set (detail[7])
  Stats stats_;       ///< this call's counters

  std::vector<Working> working_;  ///< per stage (hard, levels, min-norm)
  LsqProblem P_;
  LsqProblem Pr_;        ///< a level's warm trial in z alone (reduced_set_point)
  int slack_rows_ = 0;   ///< slack rows of the level being tried (0: none, or not a level)
  Vec y_;
  std::vector<int8_t> W_;
  std::vector<int8_t> Wp_;  ///< the pruned working set store_level_working_set tries
  Working pruned_;          ///< its rows, as a stored set (swapped into the stage's on success)

  // workspace, sized at construction (the memos' per-stage part at the second call): the
  // per-call path does not allocate after that (the closed-form SVDs are one object per
  // stage, whose sizes repeat from one call to the next)
  enum class KMode : int8_t { kZero, kWide, kTall };
  /// A stage's (hard phase, level, minimum norm) working set and K factorisations, one per
  /// stage: the trial cache finds the stage's last warm trial there at its next call.
  struct TrialState {
    WorkingQR wqr;  ///< G_w^T of the working set (k x kw), updated as rows enter and leave
    PivotedQR kqr;  ///< the projected objective K = Q N (qrows x (k - rank))
    PivotedQR cqr;  ///< [R11 R12]^T of a rank-deficient K (its minimum-norm step)
    PivotedQR kqr_t;  ///< K^T of a wide K (qrows < k - rank): its full-row-rank step
    TrapezoidRZ krz;  ///< [R11 R12] of a rank-deficient K
    Mat Qt;           ///< Q Qf
    /// kqr (and cqr) or kqr_t hold the factorisation of the current working
    /// set's K on the stage's problem (cleared whenever the working set's QR changes)
    bool k_valid = false;
    KMode k_mode = KMode::kZero;  ///< how that K was solved: negligible, by K^T, by K's QR
    int k_rank = 0;               ///< numerical rank of that K (kTall)
    bool k_rz = false;            ///< that K's minimum-norm step by krz (else cqr)
    /// qt_stale_ as factor_trial left it (the trial cache restores it with the rest)
    bool qt_stale = true;
    PivotedQR bqr;       ///< B = R^-T P^T G_w^T of a range trial (k x kw)
    bool range = false;  ///< bqr holds B of full column rank (factor_range_trial)
    /// Buffers for problems of up to cols columns, grows rows and qrows objective rows.
    void reserve(int cols, int grows, int qrows);
  };
  /// The trial cache: its value the factorisations (wqr, Qt, and K when k_valid) factor_trial
  /// made of a working set, nothing having changed them since (every update drops it); its
  /// key: the working rows of G and the objective Q, the sizes and the slack layout.
  using TrialCache = KeyedCache<TrialState, Stats, &Stats::trial_memo_hits>;
  std::vector<TrialCache> trials_;  ///< per stage (from the second call: allocate_per_stage)
  TrialCache shared_trial_;         ///< every stage's in the first call (a one-shot solve)
  TrialCache* tc_ = nullptr;        ///< the stage being solved's
  TrialState* ts_ = nullptr;        ///< its value
  bool per_stage_ = false;          ///< the per-stage caches allocated and in use
  long calls_ = 0;                  ///< solve calls so far
  /// The memos' per-stage factorisations and stored inputs, allocated at the second call
  /// (the first, and a one-shot solve, share one set; nothing allocates after the second).
  void allocate_per_stage();
  /// tc_ and ts_ set to the stage's trial state
  void enter_stage(int stage) {
    tc_ = per_stage_ ? &trials_[stage] : &shared_trial_;
    ts_ = &tc_->value;
    range_trial_ = false;
  }
  /// A level's closed form from the QR of M = A Z (one per stage): the closed-form cache finds
  /// the factorisation of the level's M of the previous call there when A and Z repeat.
  struct ClosedForm {
    PivotedQR mqr;  ///< M (tall) or M^T (wide): the closed form without an SVD
    /// rank-deficient closed form: [R11 R12]^T of a tall M (its row space, the minimum-norm
    /// solve), or [R11^T; R12^T] of a wide M (the least squares in M^T's range)
    PivotedQR tqr;
    TrapezoidRZ trz;     ///< [R11 R12] of a rank-deficient tall M
    bool wide = false;   ///< M^T factorised (me <= r)
    double smin = 0.0;   ///< lower bound 1/|R^-1|_F of sigma_min(M)
    int rank = -1;       ///< qr_factor's result (-1: the SVD path)
    /// mqr holds the factorisation of the stage's M (Ms_), svd_valid its SVD (svds_)
    bool factored = false, svd_valid = false;
    /// Buffers for a level of me equality rows in n variables, capacity inherited rows.
    void reserve(int n, int me, int capacity);
  };
  /// The closed-form cache: its value M = A Z (in Ms_) and its factorisations; its key: the
  /// level's rows A and C, r, z_identity_ and Z on entry (A and Z make M and, with A, the
  /// tolerances: functions of |A|_F, r and the damping)
  using ClosedFormCache = KeyedCache<ClosedForm, Stats, &Stats::closed_form_memo_hits>;
  std::vector<ClosedFormCache> cforms_;  ///< per stage (from the second call)
  ClosedForm shared_cf_;                 ///< every level's in the first call
  ClosedForm* cf_ = nullptr;             ///< the level being solved's
  PivotedQR fqr_;  ///< F^T of a freeze (r x f)
  PivotedQR sqr_;  ///< slack_step: the transposed system on z
  /// the stage being solved has an objective Q with orthonormal columns (the minimum-norm
  /// stage): ls_step takes the least-distance step, no Q Qf is formed
  bool unit_q_ = false;
  bool z_identity_ = false;  ///< Z_ is the n x n identity (r_ == n_: products with it are copies)
  /// the last factorisation was stored_set_point's on a level's full problem (W: its mapped
  /// set; the exact finish after a hit starts from it)
  bool trial_ready_ = false;
  /// the level being solved has P's objective Q = R P^T, R the closed form's triangular factor
  /// of full rank r, its condition within 1 / kIllConditioned, and no slack or damping rows
  /// (set by level_problem, cleared by enter_stage): its warm trials step by range_step
  bool range_trial_ = false;
  /// Qt not formed for the working set's QR (factor_working of a level with slacks and
  /// ls_step forms it when its general path needs it; updates skip it till then)
  bool qt_stale_ = true;
  /// active_set returned optimal and nothing has factorised since: wqr, widx_, Qt, res_
  /// and step_ are those of its final W and y (the exact finish's first iteration)
  bool finish_ready_ = false;
  double qscale_ = 0.0;  ///< |Q|_F of the stage being solved
  /// active_set decides stationarity and multiplier signs to rounding, not to
  /// settings.kkt_tol and a 1e-15 objective gain (the finish of an ill-conditioned or damped
  /// level)
  bool exact_ = false;
  Vec res_, dres_, step_, gvec_, u_, mu_, gy_, gp_, tvec_, rowbuf_, zc_, tmpr_, xc_, xold_,
      e_, ute_;
  std::vector<int> widx_, mov_;
  std::vector<char> keep_, viol_;
  std::vector<Mat> Ms_;  ///< per stage: the projected equalities A Z
  Mat Ab_;  ///< a level's equality rows, copied contiguous (max_eq x n): Eigen's GEMM copies a
            ///< strided (row-major input) left factor into a heap temporary otherwise
  Mat Cl_;   ///< a level's inequality rows, copied contiguous (max_in x n)
  Mat CZl_;  ///< their projection C Z (max_in x n: the left r columns)
  Mat Ztmp_;
  Vec depn_;                   ///< drop_dependent_directions: the rows' norms
  double rows_pivot_ = 1.0;    ///< level_problem: the moving rows' last kept pivot (scaled)
  std::vector<int> bidx_;      ///< add_bound_rows: the variables whose rows are kept
  Vec binv_;                   ///< add_bound_rows: their rows' reciprocal norms
  std::vector<int> brun_;      ///< add_bound_rows: the first kept row of each run, then kept
  Vec bsq_;                    ///< add_bound_rows: every bound row's squared norm
  Mat gram_;                   ///< independent_by_gram: the shifted Gram matrix, min(max_in, n)^2
  /// The freeze cache's value: a level's Z, r, z_identity_ and Cin Z after its freeze; its
  /// key: the freeze's kind and rank, Cin Z on entry, the violated rows -- and, through the
  /// closed-form cache's entry test that must hold, the level's rows and Z on entry.
  struct Frozen {
    int r = 0, kz = 0;
    bool zid = false;
    Mat Z, CinZ;
  };
  using FreezeCache = KeyedCache<Frozen, Stats, &Stats::freeze_memo_hits>;
  std::vector<FreezeCache> freezes_;  ///< per level
  std::vector<char> freeze_pending_;  ///< per level: freeze_lookup recorded, outputs due
  Mat nsp_;  ///< freeze_null_space: P N (r x (r - rank))
  Mat cztmp_;  ///< freeze_null_space: the product Cin Z P N before it is copied back
  Mat rinv_;       ///< R^-1 of the stage's mqr (a bound on M's smallest singular value)
  std::vector<Svd> svds_;
};

}  // namespace qpcoord
