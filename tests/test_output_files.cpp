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

// A fresh folder under the system's temporary folder.
std::string fresh_folder() {
    std::string t = (std::getenv("TMPDIR") ? std::string(std::getenv("TMPDIR")) : std::string("/tmp")) +
                    "/firefly-outputs-XXXXXX";
    REQUIRE(::mkdtemp(&t[0]) != nullptr);
    return t;
}

// Every name in `dir` (no recursion), sorted, comma-separated.
std::string listing(const std::string& dir) {
    std::vector<std::string> names;
    if (DIR* d = ::opendir(dir.c_str())) {
        while (const dirent* e = ::readdir(d))
            if (std::string(e->d_name) != "." && std::string(e->d_name) != "..") names.push_back(e->d_name);
        ::closedir(d);
    }
    std::sort(names.begin(), names.end());
    std::string out;
    for (const std::string& n : names) out += (out.empty() ? "" : ",") + n;
    return out;
}

// Removes the files of a flat folder (a directory among them: empty), then the folder.
void remove_folder(const std::string& dir) {
    std::string names = listing(dir);
    for (std::size_t i = 0; i < names.size();) {
        const std::size_t j = std::min(names.find(',', i), names.size());
        const std::string p = dir + "/" + names.substr(i, j - i);
        if (::unlink(p.c_str()) != 0) ::rmdir(p.c_str());
        i = j + 1;
    }
    ::rmdir(dir.c_str());
}

void write_text(firefly_tools::output_set& set, const std::string& path, const std::string& text) {
    int fd = -1;
    REQUIRE(set.open(path, fd).empty());
    REQUIRE(firefly_tools::write_all(fd, text, path).empty());
}

}  // namespace

TEST_CASE("a commit whose last rename fails takes back the renames before it", "[tools][outputs]") {
    const std::string dir = fresh_folder();
    { std::ofstream(dir + "/kept.txt") << "old"; }
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
    CHECK(listing(dir) == "blocked,kept.txt");
    remove_folder(dir);
}

TEST_CASE("a commit that succeeds replaces every file and leaves no backup", "[tools][outputs]") {
    const std::string dir = fresh_folder();
    { std::ofstream(dir + "/kept.txt") << "old"; }
    {
        firefly_tools::output_set set;
        write_text(set, dir + "/kept.txt", "new");
        write_text(set, dir + "/new.txt", "made");
        CHECK(set.commit().empty());
    }
    CHECK(read_file(dir + "/kept.txt") == "new");
    CHECK(read_file(dir + "/new.txt") == "made");
    CHECK(listing(dir) == "kept.txt,new.txt");  // no temporary, no backup
    remove_folder(dir);
}
