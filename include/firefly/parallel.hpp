// firefly: optional parallelism that never changes a bit of the result.
//
// The detector splits its work into independent tasks that write disjoint outputs, so any
// executor gives the same bytes. Serial by default; threads(n) runs tasks on a persistent
// pool of n - 1 worker threads plus the calling thread; wrap your own scheduler (TBB, a
// renderer's job system) with the constructor taking a parallel-for.
#pragma once

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>
#if defined(__cpp_exceptions)
#include <exception>
#endif

namespace firefly {

namespace detail {

// n - 1 worker threads, started on the first run() and reused by every later one; they sleep
// on a condition variable between runs (no spinning). One run at a time: a run() that finds
// the pool busy (another thread's run, or a task calling run() on its own pool) executes its
// tasks serially on the calling thread instead of waiting, so it can neither deadlock nor
// change a result. The destructor wakes and joins the workers; it must not run on one of
// them (do not let a task drop the last copy of its own executor).
//
// Without exceptions, a failure to start a std::thread (std::system_error) cannot be caught
// and terminates the program, as any std::thread use does; with exceptions the pool keeps the
// workers it could start (none: the calling thread does all the work). A task that throws
// (the detector's only throw is std::bad_alloc) ends the job: no task starts after it, and
// run() rethrows the first such exception on the calling thread once the workers are done
// with the job, whichever thread it was thrown on.
class thread_pool {
public:
    using task = std::function<void(std::size_t)>;

    // At most max_threads: a count read as "all" (unsigned(-1)) asked for 4 billion workers, and
    // reserving them ended the program without exceptions.
    static constexpr unsigned max_threads = 1024;
    explicit thread_pool(unsigned threads) : wanted_(threads > 1 ? (std::min)(threads, max_threads) - 1 : 0) {}
    thread_pool(const thread_pool&) = delete;
    thread_pool& operator=(const thread_pool&) = delete;

    ~thread_pool() {
        {
            std::lock_guard<std::mutex> l(m_);
            stop_ = true;
        }
        wake_.notify_all();
        for (auto& th : workers_) th.join();
    }

    // Calls t(i) for every i in [0, count) once and returns when all calls have finished.
    void run(std::size_t count, const task& t) {
        if (count == 0) return;
        if (count == 1 || in_use_.exchange(true, std::memory_order_acquire)) {
            for (std::size_t i = 0; i < count; ++i) t(i);
            return;
        }
        start();
        {
            std::lock_guard<std::mutex> l(m_);
            job_ = &t;
            count_ = count;
            next_.store(0, std::memory_order_relaxed);
            ++generation_;
        }
        wake_.notify_all();
#if defined(__cpp_exceptions)
        std::exception_ptr failed;
        {
            const finish_on_exit finish{*this, &failed};  // also if t throws on this thread
            guarded_work(t, count);
        }
        if (failed) std::rethrow_exception(failed);
#else
        const finish_on_exit finish{*this};
        work(t, count);
#endif
    }

    // Worker threads started so far (0 before the first run with more than one task).
    std::size_t workers() const noexcept { return started_.load(std::memory_order_relaxed); }

private:
    // Ends a run: no worker joins once job_ is cleared; waits for those that did, then frees
    // the pool for the next run.
    struct finish_on_exit {
        thread_pool& p;
#if defined(__cpp_exceptions)
        std::exception_ptr* failed;  // takes the job's first exception, before the pool is freed
#endif
        ~finish_on_exit() {
            {
                std::unique_lock<std::mutex> l(p.m_);
                p.job_ = nullptr;
                p.done_.wait(l, [this] { return p.busy_ == 0; });
#if defined(__cpp_exceptions)
                *failed = std::move(p.failed_);
                p.failed_ = nullptr;
#endif
            }
            p.in_use_.store(false, std::memory_order_release);
        }
    };

    void work(const task& t, std::size_t count) {
        for (std::size_t i; (i = next_.fetch_add(1, std::memory_order_relaxed)) < count;) t(i);
    }

#if defined(__cpp_exceptions)
    // work(), keeping the job's first exception for run() and handing out no task after it.
    void guarded_work(const task& t, std::size_t count) {
        try {
            work(t, count);
        } catch (...) {
            next_.store(count, std::memory_order_relaxed);
            std::lock_guard<std::mutex> l(m_);
            if (!failed_) failed_ = std::current_exception();
        }
    }
#endif

    // Called with in_use_ held, so by one thread at a time.
    void start() {
        if (!workers_.empty() || wanted_ == 0 || tried_) return;
        tried_ = true;
#if defined(__cpp_exceptions)
        try {
            workers_.reserve(wanted_);
            for (unsigned i = 0; i < wanted_; ++i) workers_.emplace_back([this] { loop(); });
        } catch (const std::exception&) {
            // std::system_error (no more threads) or std::bad_alloc (a count past memory):
            // keep the workers that started; the caller's thread covers the rest. Were it let
            // out, in_use_ would stay set and every later run be serial.
        }
#else
        workers_.reserve(wanted_);
        for (unsigned i = 0; i < wanted_; ++i) workers_.emplace_back([this] { loop(); });
#endif
        started_.store(workers_.size(), std::memory_order_relaxed);
    }

    void loop() {
        std::uint64_t seen = 0;
        std::unique_lock<std::mutex> l(m_);
        for (;;) {
            wake_.wait(l, [&] { return stop_ || (job_ != nullptr && generation_ != seen); });
            if (stop_) return;
            seen = generation_;
            const task* t = job_;
            const std::size_t count = count_;
            ++busy_;
            l.unlock();
#if defined(__cpp_exceptions)
            guarded_work(*t, count);
#else
            work(*t, count);
#endif
            l.lock();
            if (--busy_ == 0) done_.notify_all();
        }
    }

    const unsigned wanted_;
    std::vector<std::thread> workers_;
    std::atomic<std::size_t> started_{0};
    bool tried_ = false;
    std::atomic<bool> in_use_{false};
    std::atomic<std::size_t> next_{0};
    std::mutex m_;                     // guards everything below
    std::condition_variable wake_, done_;
    const task* job_ = nullptr;
    std::size_t count_ = 0;
    std::uint64_t generation_ = 0;
    unsigned busy_ = 0;                // workers inside the current job
#if defined(__cpp_exceptions)
    std::exception_ptr failed_;        // the current job's first exception
#endif
    bool stop_ = false;
};

}  // namespace detail

class executor {
public:
    using task = std::function<void(std::size_t)>;
    // Calls task(i) for every i in [0, count), in any order and on any thread, and returns
    // when all have finished.
    using parallel_for = std::function<void(std::size_t count, const task&)>;

    executor() = default;  // serial
    explicit executor(parallel_for f) : for_(std::move(f)) {}

    static executor serial() { return executor(); }
    // Up to n threads per run, at most 1024 (the caller's thread is one of them); n <= 1 is serial. The
    // n - 1 workers start on the first run and are shared by every copy of this executor;
    // they are joined when the last copy is destroyed. Concurrent run() calls on copies of one
    // executor do not wait for each other: the one that finds the pool busy runs its tasks on
    // its own thread. Use one threads(n) executor per rendering thread for separate pools.
    static executor threads(unsigned n) {
        if (n <= 1) return executor();
        auto pool = std::make_shared<detail::thread_pool>(n);
        return executor([pool](std::size_t count, const task& t) { pool->run(count, t); });
    }

    void run(std::size_t count, const task& t) const {
        if (for_ && count > 1) {
            for_(count, t);
        } else {
            for (std::size_t i = 0; i < count; ++i) t(i);
        }
    }
    bool is_serial() const noexcept { return !for_; }

private:
    parallel_for for_;
};

}  // namespace firefly
