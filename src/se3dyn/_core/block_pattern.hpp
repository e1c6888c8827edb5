// The compressed-column pattern of an iteration matrix made of dense blocks (se3dyn.engine.layout:
// one row per block, never one per value), and the value of every entry of it.
//
// Values are stored block after block, each block row-major at its offset. Blocks do not
// overlap, so the pattern has one entry per value (nnz = nvals); in every column the row indices
// increase. O(nvals + nb log nb) time, memory beyond the outputs: a bit per value.
#pragma once
#include <algorithm>
#include <cstdint>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace se3dyn {

// blocks: nb rows of (first row, rows, first column, columns, offset) in an N x N matrix with
// nvals values. Out: colptr (N+1), rowind (nvals), src (nvals): the value of each entry
// (position in rowind -> index in the values).
template <class SrcT>
inline void block_csc(int N, const int64_t* blocks, long nb, long nvals, int* colptr,
                      int* rowind, SrcT* src) {
  auto bad = [](const char* what) {
    throw std::invalid_argument(std::string("block pattern: ") + what);
  };
  std::fill(colptr, colptr + N + 1, 0);
  long total = 0;
  for (long b = 0; b < nb; ++b) {
    const int64_t* q = blocks + 5 * b;
    const int64_t r0 = q[0], nr = q[1], c0 = q[2], nc = q[3], off = q[4];
    if (r0 < 0 || nr < 0 || c0 < 0 || nc < 0 || r0 + nr > N || c0 + nc > N || off < 0 ||
        off + nr * nc > nvals)
      bad("block out of range");
    for (int64_t j = 0; j < nc; ++j) colptr[c0 + j + 1] += static_cast<int>(nr);
    total += nr * nc;
  }
  if (total != nvals || nvals > std::numeric_limits<int>::max()) bad("values not covered");
  for (int c = 0; c < N; ++c) colptr[c + 1] += colptr[c];
  // blocks by first column, then first row: each block's rows follow those above it
  std::vector<long> order(nb);
  std::iota(order.begin(), order.end(), 0L);
  std::sort(order.begin(), order.end(), [&](long a, long b) {
    const int64_t* p = blocks + 5 * a;
    const int64_t* q = blocks + 5 * b;
    return p[2] != q[2] ? p[2] < q[2] : p[0] < q[0];
  });
  std::vector<int> next(colptr, colptr + N), last(N, -1);
  std::vector<bool> taken(nvals, false);
  for (long t = 0; t < nb; ++t) {
    const int64_t* q = blocks + 5 * order[t];
    const int r0 = static_cast<int>(q[0]), nr = static_cast<int>(q[1]);
    const int c0 = static_cast<int>(q[2]), nc = static_cast<int>(q[3]);
    const long off = static_cast<long>(q[4]);
    for (int j = 0; j < nc; ++j) {
      const int c = c0 + j;
      if (nr > 0 && r0 <= last[c]) bad("overlapping blocks");
      int p = next[c];
      for (int i = 0; i < nr; ++i, ++p) {
        const long v = off + static_cast<long>(i) * nc + j;
        if (taken[v]) bad("overlapping values");
        taken[v] = true;
        rowind[p] = r0 + i;
        src[p] = static_cast<SrcT>(v);
      }
      next[c] = p;
      if (nr > 0) last[c] = r0 + nr - 1;
    }
  }
}

}  // namespace se3dyn
