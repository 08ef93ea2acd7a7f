// The tool's output sets (examples/output_files.hpp): a frame's files are committed whole or
// not at all, even where a rename fails after others succeeded.
#include <catch2/catch.hpp>

#include <dirent.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "output_files.hpp"

namespace {

std::string read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

bool exists(const std::string& path) {
    struct stat st {};
    return ::lstat(path.c_str(), &st) == 0;
}

// Every name in `dir` (no recursion), sorted.
std::vector<std::string> names_in(const std::string& dir) {
    std::vector<std::string> names;
    if (DIR* d = ::opendir(dir.c_str())) {
        while (const dirent* e = ::readdir(d))
            if (std::string(e->d_name) != "." && std::string(e->d_name) != "..") names.push_back(e->d_name);
        ::closedir(d);
    }
    std::sort(names.begin(), names.end());
    return names;
}

// A fresh folder under the system's temporary folder holding kept.txt ("old"), removed with
// whatever is in it (files, and directories left empty) when the test ends, passed or not.
struct folder_with_kept_file {
    std::string dir = (std::getenv("TMPDIR") ? std::string(std::getenv("TMPDIR")) : std::string("/tmp")) +
                      "/firefly-outputs-XXXXXX";
    folder_with_kept_file() {
        REQUIRE(::mkdtemp(&dir[0]) != nullptr);
        std::ofstream(dir + "/kept.txt") << "old";
    }
    ~folder_with_kept_file() {
        for (const std::string& n : names_in(dir)) {
            const std::string p = dir + "/" + n;
            if (::unlink(p.c_str()) != 0) ::rmdir(p.c_str());
        }
        ::rmdir(dir.c_str());
    }
    folder_with_kept_file(const folder_with_kept_file&) = delete;
    folder_with_kept_file& operator=(const folder_with_kept_file&) = delete;
};

void write_text(firefly_tools::output_set& set, const std::string& path, const std::string& text) {
    int fd = -1;
    REQUIRE(set.open(path, fd).empty());
    REQUIRE(firefly_tools::write_all(fd, text, path).empty());
}

}  // namespace

TEST_CASE("a commit whose last rename fails takes back the renames before it", "[tools][outputs]") {
    const folder_with_kept_file folder;
    const std::string& dir = folder.dir;
    {
        firefly_tools::output_set set;
        // renamed last opened first: new.txt, then kept.txt, then "blocked"
        write_text(set, dir + "/blocked", "never");
        write_text(set, dir + "/kept.txt", "new");
        write_text(set, dir + "/new.txt", "new");
        REQUIRE(::mkdir((dir + "/blocked").c_str(), 0700) == 0);  // a directory in the way, made after the checks
        const std::string e = set.commit();
        CHECK(e.find("cannot rename") != std::string::npos);
        CHECK(read_file(dir + "/kept.txt") == "old");  // the file it replaced is back
        CHECK_FALSE(exists(dir + "/new.txt"));         // the one it created is gone
    }
    // no temporary and no backup left once the set is gone
    CHECK(names_in(dir) == std::vector<std::string>{"blocked", "kept.txt"});
}

TEST_CASE("a commit that succeeds replaces every file and leaves no backup", "[tools][outputs]") {
    const folder_with_kept_file folder;
    const std::string& dir = folder.dir;
    {
        firefly_tools::output_set set;
        write_text(set, dir + "/kept.txt", "new");
        write_text(set, dir + "/new.txt", "made");
        CHECK(set.commit().empty());
    }
    CHECK(read_file(dir + "/kept.txt") == "new");
    CHECK(read_file(dir + "/new.txt") == "made");
    CHECK(names_in(dir) == std::vector<std::string>{"kept.txt", "new.txt"});  // no temporary, no backup
}

TEST_CASE("a replaced file keeps its permission bits; a new one gets those open() would give it", "[tools][outputs]") {
    const folder_with_kept_file folder;
    const std::string& dir = folder.dir;
    const std::string kept = dir + "/kept.txt";
    for (const mode_t mode : {mode_t{0600}, mode_t{0750}}) {  // 0750: no umask gives it to a new file
        REQUIRE(::chmod(kept.c_str(), mode) == 0);
        firefly_tools::output_set set;
        write_text(set, kept, "new");
        write_text(set, dir + "/new.txt", "made");
        REQUIRE(set.commit().empty());
        struct stat st {};
        REQUIRE(::stat(kept.c_str(), &st) == 0);
        CHECK((st.st_mode & 07777) == mode);
        REQUIRE(::stat((dir + "/new.txt").c_str(), &st) == 0);
        CHECK((st.st_mode & 07777) == firefly_tools::new_file_mode());
        REQUIRE(::unlink((dir + "/new.txt").c_str()) == 0);
    }
}
