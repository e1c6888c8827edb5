// A small fork-join pool: the caller and up to `threads() - 1` workers each take one part of a
// loop. Its users: the element kernels, frame updates and index-2 products of an iterate
// (engine.hpp), and the two halves of a dissection in the sparse LU's refactorisation and
// solves and in the LDL^T's factorisation and solves (sparse_lu.hpp, sparse_ldlt.hpp).
//
// * One pool per process (`Pool::get()`), its size set by `set_threads` (se3dyn.set_threads,
//   the SE3DYN_THREADS environment variable; default: the cores the process may run on).
// * Workers are created on the first parallel loop. Between loops they spin for a while (the
//   loops of one Newton iterate follow each other within microseconds) and then sleep on a
//   condition variable (a factorisation or a return to Python takes longer), so an idle pool
//   costs no CPU.
// * A loop that finds the pool busy (another engine running in another Python thread), or
//   that has more parts than the pool has threads, runs its parts serially in its caller, in
//   order. What each part computes never depends on how many threads run them: the callers
//   split their work so that the numbers are the same for any thread count (engine.hpp:
//   elements of one colour write disjoint entries; sparse_lu.hpp: the two parts of the
//   dissection, whatever runs them).
#pragma once
#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <new>
#include <thread>
#include <utility>
#include <vector>

#include <pthread.h>

#if defined(__x86_64__) || defined(_M_X64)
#include <immintrin.h>
#define SE3DYN_PAUSE() _mm_pause()
#else
#define SE3DYN_PAUSE() std::this_thread::yield()
#endif

namespace se3dyn {

class Pool {
 public:
  static Pool& get() {
    static Pool pool;
    return pool;
  }

  // Number of threads (the caller included) parallel loops use; n >= 1
  void set_threads(int n) {
    std::lock_guard<std::mutex> busy(run_mutex_);
    n = std::max(1, n);
    if (n < int(workers_.size()) + 1) stop();
    threads_ = n;
  }
  int threads() const { return threads_; }

  // f(p) for p in [0, parts), each part on its own thread, p = 0 in the caller. Serially (p
  // in order, in the caller) when parts == 1, when there are more parts than threads, or when
  // the pool is busy.
  template <class F>
  void run(int parts, F&& f) {
    std::unique_lock<std::mutex> busy(run_mutex_, std::try_to_lock);
    if (parts <= 1 || parts > threads_ || parts >= int(kQuit) || !busy.owns_lock()) {
      for (int p = 0; p < parts; ++p) f(p);
      return;
    }
    start(parts - 1);
    job_ = [](void* c, int p) { (*static_cast<F*>(c))(p); };
    ctx_ = &f;
    pending_.store(parts - 1, std::memory_order_relaxed);
    publish(std::uint64_t(parts));
    if (sleepers_.load(std::memory_order_acquire) > 0) wake_.notify_all();
    f(0);
    while (pending_.load(std::memory_order_acquire) != 0) SE3DYN_PAUSE();
  }

  ~Pool() { stop(); }

 private:
  Pool() {
    unsigned hw = std::thread::hardware_concurrency();
    threads_ = std::max(1, int(hw ? hw : 1));
    pthread_atfork(nullptr, nullptr, [] { Pool::get().forget(); });
  }

  // In the child of a fork: the workers did not come along. Their handles are left (joining or
  // detaching a thread of the parent is undefined), the synchronisation starts afresh.
  void forget() {
    workers_.release_all();
    new (&run_mutex_) std::mutex();
    new (&sleep_mutex_) std::mutex();
    new (&wake_) std::condition_variable();
    epoch_.store(0);
    pending_.store(0);
    sleepers_.store(0);
  }

  // thread handles that a forked child can drop without touching them
  struct Workers {
    std::vector<std::thread*> t;
    size_t size() const { return t.size(); }
    bool empty() const { return t.empty(); }
    template <class G>
    void emplace_back(G&& g) { t.push_back(new std::thread(std::forward<G>(g))); }
    void join_all() {
      for (std::thread* p : t) {
        p->join();
        delete p;
      }
      t.clear();
    }
    void release_all() { t.clear(); }
  };

  void start(int nw) {
    while (int(workers_.size()) < nw) {
      int id = int(workers_.size()) + 1;
      std::uint64_t seen = epoch_.load(std::memory_order_acquire);  // (before this loop)
      workers_.emplace_back([this, id, seen] { work(id, seen); });
    }
  }

  // A new epoch carrying the loop's number of parts (kQuit: stop). The parts travel in the
  // same atomic word as the epoch: a worker that takes no part in a loop (id >= parts) may
  // read the word late, when the caller has already gone on to the next loop, and must then
  // neither run nor count itself in that next loop from a stale part count (with 3 threads a
  // worker skipping a 2-part loop could otherwise run a part of the next loop twice).
  // (se3dyn.engine.threads.MAX_THREADS = kQuit - 1 = 254 follows these bits)
  static constexpr std::uint64_t kPartBits = 8, kQuit = (1u << kPartBits) - 1;
  void publish(std::uint64_t parts) {
    {
      std::lock_guard<std::mutex> lk(sleep_mutex_);
      const std::uint64_t e = epoch_.load(std::memory_order_relaxed);
      epoch_.store((((e >> kPartBits) + 1) << kPartBits) | parts, std::memory_order_release);
    }
  }

  void stop() {
    if (workers_.empty()) return;
    publish(kQuit);
    wake_.notify_all();
    workers_.join_all();
  }

  void work(int id, std::uint64_t seen) {
    for (;;) {
      // spin about 0.2 ms before sleeping
      std::uint64_t now = seen;
      for (int i = 0; i < 20000 && (now = epoch_.load(std::memory_order_acquire)) == seen; ++i)
        SE3DYN_PAUSE();
      if (now == seen) {
        std::unique_lock<std::mutex> lk(sleep_mutex_);
        sleepers_.fetch_add(1, std::memory_order_acq_rel);
        wake_.wait(lk, [&] { return epoch_.load(std::memory_order_acquire) != seen; });
        sleepers_.fetch_sub(1, std::memory_order_acq_rel);
        now = epoch_.load(std::memory_order_acquire);
      }
      seen = now;
      const std::uint64_t parts = now & kQuit;
      if (parts == kQuit) return;
      if (std::uint64_t(id) < parts) {
        job_(ctx_, id);
        pending_.fetch_sub(1, std::memory_order_acq_rel);
      }
    }
  }

  int threads_ = 1;
  Workers workers_;
  std::mutex run_mutex_;    // one parallel loop at a time
  std::mutex sleep_mutex_;  // workers sleeping between loops
  std::condition_variable wake_;
  std::atomic<std::uint64_t> epoch_{0};  // (loop count << kPartBits) | parts
  std::atomic<int> pending_{0};
  std::atomic<int> sleepers_{0};
  void (*job_)(void*, int) = nullptr;
  void* ctx_ = nullptr;
};

}  // namespace se3dyn
