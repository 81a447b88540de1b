#pragma once

// Helpers shared by the dataset tests (frame_source_test.cpp and friends):
// temporary directories, small files and images, and a text mutator for the
// fuzz tests.

#include <algorithm>
#include <array>
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <random>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <unistd.h>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "temp_dir.h"

namespace scaled::drivers::test {

inline std::string readFile(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

inline void writeFile(const std::filesystem::path& path, std::string_view content) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << content;
    ASSERT_TRUE(out.good()) << "cannot write " << path;
}

// A fresh, uniquely named directory, removed at the end (tests/support/temp_dir.h).
using scaled::test::TempDir;

// A small 8x6 BGR image with a pattern depending on `seed`.
inline cv::Mat tinyImage(int seed) {
    cv::Mat img(6, 8, CV_8UC3);
    for (int r = 0; r < img.rows; ++r) {
        for (int c = 0; c < img.cols; ++c) {
            img.at<cv::Vec3b>(r, c) = cv::Vec3b(static_cast<uchar>((r * 31 + seed * 7) & 0xff),
                                                static_cast<uchar>((c * 17 + seed) & 0xff),
                                                static_cast<uchar>((r * c + seed * 3) & 0xff));
        }
    }
    return img;
}

// Random damage to the text of an index file: byte flips, truncation,
// duplicated, deleted or swapped lines, inserted garbage, a field replaced by
// one of `tokens`, or the whole text emptied.
// A new empty directory dir/runN for fuzz iteration N, the previous one
// removed (rewriting files in place is slow on ext4, which flushes
// truncated-and-rewritten files on close).
inline std::filesystem::path freshRunDir(const std::filesystem::path& dir, int iteration,
                                         const std::filesystem::path& previous) {
    std::error_code ec;
    std::filesystem::remove_all(previous, ec);
    std::filesystem::path run = dir / ("run" + std::to_string(iteration));
    std::filesystem::create_directory(run);
    return run;
}

class TextMutator {
public:
    TextMutator(unsigned seed, std::vector<std::string> tokens)
        : rng_(seed), tokens_(std::move(tokens)) {}

    std::size_t pick(std::size_t n) {
        return n == 0 ? std::size_t{0} : std::uniform_int_distribution<std::size_t>(0, n - 1)(rng_);
    }

    // A copy of `texts` with 1-3 mutations, each in a randomly chosen text.
    template <std::size_t N>
    std::array<std::string, N> mutated(const std::array<std::string, N>& texts) {
        std::array<std::string, N> out = texts;
        const std::size_t n = 1 + pick(3);
        for (std::size_t m = 0; m < n; ++m) {
            mutate(out[pick(N)]);
        }
        return out;
    }

    void mutate(std::string& s) {
        static constexpr std::string_view kGarbage = "0123456789.-+eE naif#/\t\r\nxyz";
        switch (pick(8)) {
            case 0:  // byte flip
                if (!s.empty()) {
                    s[pick(s.size())] = static_cast<char>(pick(256));
                }
                break;
            case 1:  // truncation
                s.resize(pick(s.size() + 1));
                break;
            case 2: {  // duplicated line
                auto ls = splitLines(s);
                if (!ls.empty()) {
                    const std::size_t k = pick(ls.size());
                    ls.insert(ls.begin() + static_cast<std::ptrdiff_t>(pick(ls.size() + 1)), ls[k]);
                }
                s = joinLines(ls);
                break;
            }
            case 3: {  // deleted line
                auto ls = splitLines(s);
                if (!ls.empty()) {
                    ls.erase(ls.begin() + static_cast<std::ptrdiff_t>(pick(ls.size())));
                }
                s = joinLines(ls);
                break;
            }
            case 4: {  // inserted garbage
                std::string g;
                const std::size_t len = 1 + pick(12);
                for (std::size_t k = 0; k < len; ++k) {
                    g += pick(8) == 0 ? static_cast<char>(pick(256))
                                      : kGarbage[pick(kGarbage.size())];
                }
                s.insert(pick(s.size() + 1), g);
                break;
            }
            case 5: {  // swapped lines
                auto ls = splitLines(s);
                if (ls.size() > 1) {
                    std::swap(ls[pick(ls.size())], ls[pick(ls.size())]);
                }
                s = joinLines(ls);
                break;
            }
            case 6: {  // a field replaced by an extreme or odd token
                auto ls = splitLines(s);
                if (!ls.empty() && !tokens_.empty()) {
                    std::string& l = ls[pick(ls.size())];
                    std::vector<std::string> fields;
                    std::istringstream in(l);
                    std::string f;
                    while (in >> f) {
                        fields.push_back(f);
                    }
                    if (!fields.empty()) {
                        fields[pick(fields.size())] = tokens_[pick(tokens_.size())];
                        l.clear();
                        for (const auto& x : fields) {
                            l += x + " ";
                        }
                    }
                }
                s = joinLines(ls);
                break;
            }
            default:  // a whole file emptied
                s.clear();
                break;
        }
    }

private:
    static std::vector<std::string> splitLines(const std::string& s) {
        std::vector<std::string> ls;
        std::istringstream in(s);
        std::string l;
        while (std::getline(in, l)) {
            ls.push_back(l);
        }
        return ls;
    }
    static std::string joinLines(const std::vector<std::string>& ls) {
        std::string s;
        for (const auto& l : ls) {
            s += l;
            s += '\n';
        }
        return s;
    }

    std::mt19937 rng_;
    std::vector<std::string> tokens_;
};

}  // namespace scaled::drivers::test
