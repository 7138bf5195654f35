// SPDX-License-Identifier: MIT
#include "sequence.hpp"

#include "io/error.hpp"
#include "io/mesh.hpp"
#include "io/particles.hpp"
#include "report.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <system_error>

namespace fs = std::filesystem;

namespace nbmc::cli {

namespace {

struct Range {
  bool set = false;
  std::int64_t a = 0, b = 0, step = 1;
  bool contains(std::int64_t v) const { return !set || (v >= a && v <= b && (v - a) % step == 0); }
};

bool parse_int(const std::string& s, std::int64_t& v) {
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size() && v >= 0;
}

bool parse_range(const std::string& spec, Range& r, std::string& error) {
  if (spec.empty()) return true;
  std::vector<std::string> parts;
  std::size_t start = 0;
  for (;;) {
    const std::size_t c = spec.find(':', start);
    parts.push_back(spec.substr(start, c == std::string::npos ? std::string::npos : c - start));
    if (c == std::string::npos) break;
    start = c + 1;
  }
  if (parts.size() < 2 || parts.size() > 3 || !parse_int(parts[0], r.a) || !parse_int(parts[1], r.b) ||
      (parts.size() == 3 && (!parse_int(parts[2], r.step) || r.step == 0)) || r.b < r.a) {
    error = "--frames '" + spec + "' is not A:B or A:B:STEP (non-negative integers, A <= B, STEP >= 1)";
    return false;
  }
  r.set = true;
  return true;
}

std::string replace_braces(const std::string& pattern, const std::string& label) {
  std::string out;
  for (std::size_t i = 0; i < pattern.size();) {
    if (pattern.compare(i, 2, "{}") == 0) {
      out += label;
      i += 2;
    } else {
      out += pattern[i++];
    }
  }
  return out;
}

std::size_t count_braces(const std::string& s) {
  std::size_t n = 0;
  for (std::size_t p = s.find("{}"); p != std::string::npos; p = s.find("{}", p + 2)) ++n;
  return n;
}

std::string grouped(std::uint64_t v) {
  std::string d = std::to_string(v), out;
  for (std::size_t i = 0; i < d.size(); ++i) {
    out += d[i];
    if (i + 1 < d.size() && (d.size() - 1 - i) % 3 == 0) out += ',';
  }
  return out;
}

std::string clock_text(double s) {
  if (!(s >= 0) || !std::isfinite(s)) s = 0;
  const long long t = static_cast<long long>(s + 0.5);
  char buf[32];
  if (t >= 3600)
    std::snprintf(buf, sizeof buf, "%lld:%02lld:%02lld", t / 3600, (t / 60) % 60, t % 60);
  else
    std::snprintf(buf, sizeof buf, "%lld:%02lld", t / 60, t % 60);
  return buf;
}

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

// An .h5 output with {} in its name: all frames go into one HDF5 file (the
// name without {} and a separator next to it), one group "frame_<n>" each.
// A pattern naming the group itself ('all.h5:/step_{}') is left as it is.
void frames_into_one_hdf5(const std::string& output, std::vector<Frame>& frames) {
  const std::string plain = replace_braces(output, "");
  try {
    if (nbmc::io::mesh_format(plain) != "h5" || nbmc::io::mesh_output_file(plain) != plain) return;
  } catch (const nbmc::io::Error&) {
    return; // reported when the first frame is written
  }
  std::string file = output;
  const std::size_t at = file.rfind("{}");
  const std::size_t from = at > 0 && std::strchr("_-.", file[at - 1]) ? at - 1 : at;
  file = replace_braces(file.erase(from, at + 2 - from), "");
  const std::size_t slash = file.find_last_of('/');
  const std::size_t name = slash == std::string::npos ? 0 : slash + 1;
  if (name < file.size() && file[name] == '.') file.insert(name, "frames"); // 'out/{}.h5' -> 'out/frames.h5'
  for (Frame& f : frames) f.output = file + ":/frame_" + f.label;
}

} // namespace

std::string without_braces(const std::string& path) { return replace_braces(path, ""); }

bool output_exists(const std::string& path) { return nbmc::io::mesh_output_exists(path); }

void make_parent_folders(const std::string& path) {
  const fs::path parent = fs::path(nbmc::io::mesh_output_file(path)).parent_path();
  if (parent.empty()) return;
  std::error_code ec;
  fs::create_directories(parent, ec); // a failure shows when the mesh is written
}

bool plan_sequence(const std::string& input, const std::string& output, const std::string& format,
                   const std::string& frames_spec, SequencePlan& plan, std::string& error) {
  plan = SequencePlan{};
  Range range;
  if (!parse_range(frames_spec, range, error)) {
    plan.usage_error = true;
    return false;
  }
  const std::size_t in_braces = count_braces(input), out_braces = count_braces(output);
  if (in_braces > 1) {
    error = "the input pattern may contain {} only once";
    plan.usage_error = true;
    return false;
  }
  if (in_braces == 1) {
    if (out_braces == 0) {
      error = "the input '" + input + "' is a sequence: put {} in the output name too (e.g. -o 'out/surface_{}.ply')";
      plan.usage_error = true;
      return false;
    }
    const fs::path pattern(input);
    const std::string file = pattern.filename().string();
    const std::size_t at = file.find("{}");
    if (at == std::string::npos) {
      error = "{} must be in the file name of the input pattern, not in a folder name";
      plan.usage_error = true;
      return false;
    }
    const std::string prefix = file.substr(0, at), suffix = file.substr(at + 2);
    const fs::path dir = pattern.has_parent_path() ? pattern.parent_path() : fs::path(".");
    struct Match {
      std::int64_t n;
      std::string digits, path;
    };
    std::vector<Match> matches;
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
      const std::string name = it->path().filename().string();
      if (name.size() <= prefix.size() + suffix.size() || name.compare(0, prefix.size(), prefix) != 0 ||
          name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0)
        continue;
      const std::string digits = name.substr(prefix.size(), name.size() - prefix.size() - suffix.size());
      if (digits.size() > 18 || !std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; }))
        continue;
      std::error_code ec2;
      if (!it->is_regular_file(ec2)) continue;
      Match m;
      parse_int(digits, m.n);
      m.digits = digits;
      m.path = pattern.has_parent_path() ? (pattern.parent_path() / name).string() : name;
      matches.push_back(std::move(m));
    }
    if (ec) {
      error = dir.string() + ": cannot list the folder: " + ec.message();
      return false;
    }
    std::sort(matches.begin(), matches.end(),
              [](const Match& a, const Match& b) { return a.n != b.n ? a.n < b.n : a.digits < b.digits; });
    std::vector<bool> seen;
    for (const Match& m : matches) {
      if (!range.contains(m.n)) continue;
      Frame f;
      f.label = m.digits;
      f.input = m.path;
      f.output = replace_braces(output, m.digits);
      plan.frames.push_back(std::move(f));
    }
    if (range.set) {
      // Frames asked for that have no file are failures of their own.
      for (std::int64_t v = range.a; v <= range.b; v += range.step) {
        bool found = false;
        for (const Match& m : matches) found = found || m.n == v;
        if (found) continue;
        Frame f;
        f.label = std::to_string(v);
        f.input = replace_braces(input, f.label);
        f.output = replace_braces(output, f.label);
        f.missing = "no file matches '" + input + "' with number " + f.label;
        const auto pos = std::find_if(plan.frames.begin(), plan.frames.end(), [&](const Frame& g) {
          std::int64_t n = 0;
          parse_int(g.label, n);
          return n > v;
        });
        plan.frames.insert(pos, std::move(f));
        if (plan.frames.size() > 10000000) break;
      }
    }
    if (plan.frames.empty()) {
      error = matches.empty() ? "no file matches '" + input + "'" : "no file of '" + input + "' is within --frames";
      return false;
    }
    frames_into_one_hdf5(output, plan.frames);
    plan.is_sequence = true;
    return true;
  }

  // One input file: H5Part files may hold several steps.
  std::string f;
  std::vector<std::int64_t> steps;
  try {
    f = nbmc::io::particle_format(input, format);
    if (f == "h5part" || f == "hdf5") steps = nbmc::io::list_frames(input, format);
  } catch (const nbmc::io::Error& e) {
    error = e.what();
    return false;
  }
  if (steps.empty()) {
    if (out_braces) {
      error = "the output has {} but the input '" + input + "' is a single frame (use {} in the input for a sequence)";
      plan.usage_error = true;
      return false;
    }
    if (range.set) {
      error = "--frames applies to sequences ({} in the input, or a multi-step H5Part file)";
      plan.usage_error = true;
      return false;
    }
    return true;
  }
  std::vector<std::int64_t> chosen;
  for (std::int64_t s : steps)
    if (range.contains(s)) chosen.push_back(s);
  if (out_braces == 0) {
    if (range.set && chosen.size() != 1) {
      error = "--frames selects " + std::to_string(chosen.size()) +
              " steps but the output has no {} (put {} in the output name for several)";
      plan.usage_error = true;
      return false;
    }
    plan.step = range.set ? chosen.front() : steps.front();
    return true;
  }
  if (chosen.empty()) {
    error = input + ": no step within --frames (the file has steps " + std::to_string(steps.front()) + " to " +
            std::to_string(steps.back()) + ")";
    return false;
  }
  for (std::int64_t s : chosen) {
    Frame fr;
    fr.label = std::to_string(s);
    fr.input = input;
    fr.step = s;
    fr.output = replace_braces(output, fr.label);
    plan.frames.push_back(std::move(fr));
  }
  frames_into_one_hdf5(output, plan.frames);
  plan.is_sequence = true;
  return true;
}

std::string progress_line(std::size_t index, std::size_t total, const FrameResult& r, const RateMeter& m) {
  const int width = static_cast<int>(std::to_string(total).size());
  char head[64];
  std::snprintf(head, sizeof head, "[%*zu/%zu] frame %s: ", width, index, total, r.label.c_str());
  std::string line = head;
  if (r.status == "written")
    line += grouped(r.particles) + " particles -> " + r.output + " (" + grouped(r.triangles) + " triangles, " +
            number(r.seconds) + " s)";
  else if (r.status == "skipped")
    line += "skipped, " + r.output + " exists";
  else
    line += "FAILED";
  line += " | " + number(m.rate()) + " frames/s, " + clock_text(m.remaining_seconds()) + " left\n";
  return line;
}

std::string format_sequence(const SequenceReport& r) {
  std::string o;
  o += "nbmc       " + r.version + "\n";
  o += "frames     " + std::to_string(r.frames.size()) + " (" + std::to_string(r.count("written")) + " written, " +
       std::to_string(r.count("skipped")) + " skipped, " + std::to_string(r.failed()) + " failed)\n";
  o += "backend    " + r.backend + "\n";
  std::uint64_t tris = 0;
  for (const FrameResult& f : r.frames) tris += f.triangles;
  o += "triangles  " + grouped(tris) + " in all\n";
  o += "total      " + number(r.total_seconds) + " s\n";
  for (const FrameResult& f : r.frames)
    if (f.status == "failed") o += "failed     frame " + f.label + " (" + f.input + "): " + f.error + "\n";
  return o;
}

std::string format_sequence_json(const SequenceReport& r) {
  const auto num = [](double v) {
    if (!std::isfinite(v)) return std::string("null");
    char buf[64];
    const auto res = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, res.ptr);
  };
  std::string o = "{\n";
  o += "  \"nbmc_version\": " + json_string(r.version) + ",\n";
  o += "  \"backend\": " + json_string(r.backend) + ",\n";
  o += "  \"spacing\": " + num(r.params.spacing) + ",\n";
  o += "  \"frames\": [";
  for (std::size_t i = 0; i < r.frames.size(); ++i) {
    const FrameResult& f = r.frames[i];
    o += i ? ",\n    " : "\n    ";
    o += "{\"label\": " + json_string(f.label) + ", \"input\": " + json_string(f.input) +
         ", \"output\": " + json_string(f.output) + ", \"status\": " + json_string(f.status) +
         ", \"particle_count\": " + std::to_string(f.particles) + ", \"vertex_count\": " + std::to_string(f.vertices) +
         ", \"triangle_count\": " + std::to_string(f.triangles) + ", \"seconds\": " + num(f.seconds) +
         ", \"read_seconds\": " + num(f.read_seconds) + ", \"reconstruct_seconds\": " + num(f.reconstruct_seconds) +
         ", \"write_seconds\": " + num(f.write_seconds);
    if (!f.error.empty()) o += ", \"error\": " + json_string(f.error);
    o += "}";
  }
  o += r.frames.empty() ? "],\n" : "\n  ],\n";
  o += "  \"written\": " + std::to_string(r.count("written")) + ", \"skipped\": " + std::to_string(r.count("skipped")) +
       ", \"failed\": " + std::to_string(r.failed()) + ",\n";
  o += "  \"total_seconds\": " + num(r.total_seconds) + "\n}\n";
  return o;
}

} // namespace nbmc::cli
