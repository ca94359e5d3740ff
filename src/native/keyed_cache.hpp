// qpcoord native engine: a cache entry keyed on the bits of its inputs (the engine's four
// caches -- closed form, freeze, trial, bound rows -- are instances of KeyedCache).
// Header-only.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstring>
#include <vector>

namespace qpcoord {

/// One cache entry: a value computed from some inputs, kept with the bits of those inputs
/// (its key) and a hit counter.
///
/// A lookup gives the inputs part by part, always in the same order (begin(), then same()
/// per part). While every part given is the key's, bit for bit (0.0 and -0.0 differ), the
/// key is only compared; from the first part that differs the entry holds nothing any more
/// and each part given from there on is *recorded* as the new key instead. holds() then says
/// whether the entry's value is the one computing from these inputs would give; if not, the
/// caller computes it into `value` and calls store(). A value is a deterministic function of
/// its key, so a hit returns exactly what computing returns.
///
/// A lookup may stop after any part (the parts after it are not recorded): a later lookup
/// compares the recorded part and records the rest. store() after such a lookup would make an
/// entry of part of its inputs: the caller stores only after a lookup that gave every part.
///
/// The key's storage is reserved once (reserve_key); a key that does not fit is not
/// recorded and its entry holds nothing: a lookup never allocates.
/// Hits: the counter of Counters that hit() increments.
template <class Value, class Counters, int Counters::*Hits>
class KeyedCache {
 public:
  Value value;  ///< what computing from the key's inputs gave (while holds())

  /// Room for a key of up to `bytes` bytes.
  void reserve_key(std::size_t bytes) { key_.assign(bytes, 0); }

  /// Starts a lookup: the next part given is compared with the key's first.
  void begin() {
    pos_ = 0;
    same_ = true;
    fits_ = true;
  }

  /// The next part: `bytes` contiguous bytes at p. True while every part of this lookup so
  /// far is the key's.
  bool same(const void* p, std::size_t bytes) {
    if (same_ && pos_ + bytes <= recorded_ &&
        (bytes == 0 || std::memcmp(key_.data() + pos_, p, bytes) == 0)) {
      pos_ += bytes;
      return true;
    }
    if (!reserve_part(bytes)) return false;
    if (bytes) std::memcpy(key_.data() + pos_, p, bytes);
    return end_part(bytes);
  }
  bool same(int v) { return same(&v, sizeof v); }

  /// The next part: an m x n block of doubles with any strides (rows or columns contiguous,
  /// or neither: entry by entry). Its layout and sizes are part of the key, then its entries
  /// in that layout: one comparison for a block whose entries follow each other.
  template <typename Block>
  bool same_block(const Block& a) {
    const Eigen::Index m = a.rows(), n = a.cols();
    int layout = 1;  // rows contiguous (1), columns (2), neither (3)
    if (m > 0 && n > 0) layout = (a.innerStride() != 1 && a.outerStride() != 1) ? 3
                                 : (a.outerStride() == 1)                       ? 1
                                                                                : 2;
    bool ok = same(layout);
    ok = same(static_cast<int>(m)) && ok;
    ok = same(static_cast<int>(n)) && ok;
    if (m == 0 || n == 0) return ok;
    if (layout == 3) {
      for (Eigen::Index j = 0; j < n; ++j) ok = same_strided(&a.coeff(0, j), m, a.innerStride()) && ok;
      return ok;
    }
    Eigen::Index runs = (layout == 1) ? m : n, len = (layout == 1) ? n : m;
    const Eigen::Index stride = (layout == 1) ? a.innerStride() : a.outerStride();
    if (stride == len) {  // the runs follow each other: one
      len *= runs;
      runs = 1;
    }
    for (Eigen::Index k = 0; k < runs; ++k)
      ok = same(a.data() + k * stride, sizeof(double) * len) && ok;
    return ok;
  }

  /// The next part: rows `rows` of G, their first k entries each (their count, the indices,
  /// then the entries row after row).
  template <typename Matrix>
  bool same_rows(const Matrix& G, const std::vector<int>& rows, int k) {
    bool ok = same(static_cast<int>(rows.size()));
    ok = same(rows.data(), sizeof(int) * rows.size()) && ok;
    for (const int i : rows) ok = same_strided(&G.coeff(i, 0), k, G.outerStride()) && ok;
    return ok;
  }

  /// The entry test: the value is the one of the inputs given since begin() (every part the
  /// key's, the key no longer than them).
  bool holds() const { return valid_ && same_ && pos_ == recorded_; }

  /// holds(), and when it does the hit is counted in c.
  bool hit(Counters& c) {
    if (!holds()) return false;
    ++(c.*Hits);
    return true;
  }

  /// value now holds what computing from the inputs of this lookup gave (every part given).
  void store() { valid_ = fits_ && pos_ == recorded_; }

  /// value changed (or is about to): the entry holds nothing; the key stays.
  void drop() { valid_ = false; }

  /// Nothing held, nothing recorded: the next lookup records every part.
  void forget() {
    valid_ = false;
    recorded_ = 0;
  }

 private:
  /// The next part: count doubles at p, stride apart (entry by entry: a row of a
  /// column-major matrix).
  bool same_strided(const double* p, Eigen::Index count, Eigen::Index stride) {
    const std::size_t bytes = sizeof(double) * static_cast<std::size_t>(count);
    if (same_ && pos_ + bytes <= recorded_) {
      const unsigned char* k = key_.data() + pos_;
      Eigen::Index i = 0;
      while (i < count && std::memcmp(k + sizeof(double) * i, p + i * stride, sizeof(double)) == 0)
        ++i;
      if (i == count) {
        pos_ += bytes;
        return true;
      }
    }
    if (!reserve_part(bytes)) return false;
    for (Eigen::Index i = 0; i < count; ++i)
      std::memcpy(key_.data() + pos_ + sizeof(double) * i, p + i * stride, sizeof(double));
    return end_part(bytes);
  }

  /// A part differs: the entry holds nothing; true when the part fits the key after pos_
  /// (else the key is unusable until a lookup's parts all fit).
  bool reserve_part(std::size_t bytes) {
    same_ = false;
    valid_ = false;
    if (fits_ && pos_ + bytes <= key_.size()) return true;
    fits_ = false;
    recorded_ = 0;
    return false;
  }
  /// The part was recorded at pos_: the key ends after it. Returns false (it differed).
  bool end_part(std::size_t bytes) {
    pos_ += bytes;
    recorded_ = pos_;
    return false;
  }

  std::vector<unsigned char> key_;  ///< the key's bits (capacity: reserve_key)
  std::size_t recorded_ = 0;        ///< bytes of key_ recorded
  std::size_t pos_ = 0;             ///< bytes given in this lookup
  bool same_ = false;               ///< every part of this lookup so far was the key's
  bool fits_ = true;                ///< every part of this lookup so far fitted key_
  bool valid_ = false;              ///< value is the one of the recorded key
};

}  // namespace qpcoord
