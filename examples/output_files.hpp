// Output files for the command-line tool: file identity (an output must never be an input,
// whatever its spelling) and outputs written as a set of exclusive temporaries that are
// renamed over their final names only when every one of them is complete.
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace firefly_tools {

// What a path names. An existing file is its (device, inode), so hard links, symlinks and
// different spellings of one file compare equal; a file yet to be created is its folder's
// (device, inode) and its name in that folder.
struct file_id {
    dev_t dev = 0;
    ino_t ino = 0;
    std::string leaf;  // empty for an existing file
    bool operator==(const file_id& o) const { return dev == o.dev && ino == o.ino && leaf == o.leaf; }
    // An order, for sets of ids: a sequence of K buffers names K files per frame.
    bool operator<(const file_id& o) const {
        if (dev != o.dev) return dev < o.dev;
        if (ino != o.ino) return ino < o.ino;
        return leaf < o.leaf;
    }
};

inline std::string parent_dir(const std::string& path) {
    const std::size_t slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    return slash == 0 ? "/" : path.substr(0, slash);
}
inline std::string leaf_name(const std::string& path) {
    const std::size_t slash = path.find_last_of('/');
    return slash == std::string::npos ? path : path.substr(slash + 1);
}

// False when neither the file nor its folder can be found.
inline bool identify(const std::string& path, file_id& id) {
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0) {
        id = {st.st_dev, st.st_ino, {}};
        return true;
    }
    if (::stat(parent_dir(path).c_str(), &st) != 0) return false;
    id = {st.st_dev, st.st_ino, leaf_name(path)};
    return true;
}

// The permission bits a plain open() would give a new file (0666 less the umask).
inline mode_t new_file_mode() {
    static const mode_t mode = [] {
        const mode_t mask = ::umask(0);
        ::umask(mask);
        return static_cast<mode_t>(0666 & ~mask);
    }();
    return mode;
}

// The permission bits of the output that will be at `path`: those of the regular file it
// replaces (a private output stays private), or a new file's. Set-id and sticky bits are not
// carried over to new content.
inline mode_t output_mode(const std::string& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode)) return st.st_mode & 0777;
    return new_file_mode();
}

// Outputs written together: open() creates an exclusive temporary next to each final name
// (mkstemp: O_CREAT | O_EXCL, so a planted name or symlink is never opened), commit() renames
// them in reverse order of opening (the first output opened, the main one, appears last).
// Whatever is not committed is removed when the set is destroyed.
class output_set {
public:
    output_set() = default;
    output_set(const output_set&) = delete;
    output_set& operator=(const output_set&) = delete;
    output_set(output_set&& o) noexcept : files_(std::move(o.files_)) { o.files_.clear(); }
    output_set& operator=(output_set&& o) noexcept {
        if (this != &o) {
            discard();
            files_ = std::move(o.files_);
            o.files_.clear();
        }
        return *this;
    }
    ~output_set() { discard(); }

    // Opens a temporary for `path`, with the mode the output is to have; `fd` receives its
    // descriptor (owned by the set).
    std::string open(const std::string& path, int& fd) {
        std::string leaf = leaf_name(path);
        if (leaf.size() > 200) leaf.resize(200);  // the temporary's name must fit NAME_MAX
        std::string tmpl = parent_dir(path) + "/." + leaf + ".tmp-XXXXXX";
        fd = ::mkstemp(&tmpl[0]);
        if (fd < 0) return "cannot create a temporary for " + path + ": " + std::strerror(errno);
        files_.push_back({path, tmpl, fd});
        if (::fchmod(fd, output_mode(path)) != 0) return "cannot set the mode of " + tmpl;
        return {};
    }
    // Closes every descriptor (reporting a failed close, e.g. a full disk).
    std::string close_all() {
        std::string e;
        for (auto& f : files_)
            if (f.fd >= 0) {
                if (::close(f.fd) != 0 && e.empty()) e = "write failed: " + f.final_name;
                f.fd = -1;
            }
        return e;
    }
    // Renames every temporary over its final name, last opened first. Where a rename fails
    // (the tool's checks before writing find what can be foreseen: a directory or a device in
    // the way, a name too long), the ones before it are undone: a final name that held a file
    // gets it back (kept by a hard link where the file system has them), one that held none
    // is removed. So a set is committed whole or not at all.
    std::string commit() {
        std::string e = close_all();
        if (!e.empty()) return e;
        std::vector<renamed> done;
        while (!files_.empty()) {
            const entry& f = files_.back();
            struct stat st {};
            renamed r{f.final_name, f.temp + ".old", ::lstat(f.final_name.c_str(), &st) == 0};
            if (!r.replaced || ::link(f.final_name.c_str(), r.backup.c_str()) != 0) r.backup.clear();
            if (std::rename(f.temp.c_str(), f.final_name.c_str()) != 0) {
                e = "cannot rename " + f.temp + " to " + f.final_name + ": " + std::strerror(errno);
                if (!r.backup.empty()) ::unlink(r.backup.c_str());
                undo(done);
                return e;
            }
            done.push_back(std::move(r));
            files_.pop_back();
        }
        for (const renamed& r : done)
            if (!r.backup.empty()) ::unlink(r.backup.c_str());
        return {};
    }
    // Removes every temporary not yet renamed.
    void discard() {
        (void)close_all();
        for (const auto& f : files_) std::remove(f.temp.c_str());
        files_.clear();
    }

private:
    struct entry {
        std::string final_name, temp;
        int fd;
    };
    struct renamed {
        std::string final_name, backup;  // backup: a hard link to the file it replaced, or empty
        bool replaced = false;           // a file stood at final_name before the rename
    };
    // Takes back the renames of a commit that failed, last first.
    static void undo(const std::vector<renamed>& done) {
        for (auto r = done.rbegin(); r != done.rend(); ++r) {
            if (!r->backup.empty()) (void)std::rename(r->backup.c_str(), r->final_name.c_str());
            else if (!r->replaced) (void)::unlink(r->final_name.c_str());
        }
    }
    std::vector<entry> files_;
};

// Writes all of `text` to `fd`.
inline std::string write_all(int fd, const std::string& text, const std::string& name) {
    const char* p = text.data();
    std::size_t left = text.size();
    while (left > 0) {
        const ssize_t k = ::write(fd, p, left);
        if (k < 0 && errno == EINTR) continue;
        if (k <= 0) return "write failed: " + name;
        p += k;
        left -= static_cast<std::size_t>(k);
    }
    return {};
}

}  // namespace firefly_tools
