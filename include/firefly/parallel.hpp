// firefly: optional parallelism that never changes a bit of the result.
//
// The detector splits its work into independent tasks that write disjoint outputs (the two
// half buffers), so any executor gives the same bytes. Serial by default; threads(n) runs
// tasks on std::threads; wrap your own scheduler (TBB, a renderer's job system) with the
// constructor taking a parallel-for.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <functional>
#include <thread>
#include <vector>

namespace firefly {

class executor {
public:
    using task = std::function<void(std::size_t)>;
    // Calls task(i) for every i in [0, count), in any order and on any thread, and returns
    // when all have finished.
    using parallel_for = std::function<void(std::size_t count, const task&)>;

    executor() = default;  // serial
    explicit executor(parallel_for f) : for_(std::move(f)) {}

    static executor serial() { return executor(); }
    // Up to n threads per call (the caller's thread is one of them); n <= 1 is serial.
    static executor threads(unsigned n) {
        if (n <= 1) return executor();
        return executor([n](std::size_t count, const task& t) {
            std::atomic<std::size_t> next{0};
            auto worker = [&] {
                for (std::size_t i; (i = next.fetch_add(1)) < count;) t(i);
            };
            const std::size_t extra = std::min<std::size_t>(n, count) - (count > 0 ? 1 : 0);
            std::vector<std::thread> pool;
            pool.reserve(extra);
            for (std::size_t i = 0; i < extra; ++i) pool.emplace_back(worker);
            worker();
            for (auto& th : pool) th.join();
        });
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
