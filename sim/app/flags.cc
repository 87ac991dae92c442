#include "sim/app/flags.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>

namespace sandtable::sim {

Expected<Flags> Flags::Parse(const std::vector<std::string>& args, const FlagSpec& spec) {
  Flags flags;
  for (size_t i = 0; i < args.size(); ++i) {
    std::string name = args[i];
    if (name.size() < 2 || name[0] != '-') {
      return InvalidArgumentError("unexpected argument '" + name + "' (flags start with -)");
    }
    std::string value;
    bool has_inline_value = false;
    const size_t equals = name.find('=');
    if (equals != std::string::npos) {
      value = name.substr(equals + 1);
      name = name.substr(0, equals);
      has_inline_value = true;
    }
    if (spec.switches.count(name)) {
      if (has_inline_value) return InvalidArgumentError(name + " takes no value");
      flags.switches_.insert(name);
      continue;
    }
    const bool single = spec.values.count(name) > 0;
    if (!single && !spec.repeated.count(name)) {
      return InvalidArgumentError("unknown flag " + name);
    }
    if (!has_inline_value) {
      if (i + 1 >= args.size()) return InvalidArgumentError("missing value after " + name);
      value = args[++i];
    }
    if (single && flags.values_.count(name)) {
      return InvalidArgumentError(name + " given more than once");
    }
    flags.values_[name].push_back(value);
  }
  for (const std::string& name : spec.required) {
    if (!flags.values_.count(name)) return InvalidArgumentError("missing required flag " + name);
  }
  return flags;
}

std::string Flags::Get(const std::string& name, const std::string& fallback) const {
  auto it = values_.find(name);
  return it == values_.end() ? fallback : it->second.front();
}

std::vector<std::string> Flags::GetAll(const std::string& name) const {
  auto it = values_.find(name);
  return it == values_.end() ? std::vector<std::string>{} : it->second;
}

Expected<int64_t> Flags::GetInt(const std::string& name, int64_t fallback, int64_t lo,
                                int64_t hi) const {
  if (!values_.count(name)) return fallback;
  const std::string text = Get(name);
  errno = 0;
  char* end = nullptr;
  const long long value = std::strtoll(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || errno == ERANGE || value < lo || value > hi) {
    return InvalidArgumentError(name + " = '" + text + "' must be an integer in [" +
                                std::to_string(lo) + ", " + std::to_string(hi) + "]");
  }
  return static_cast<int64_t>(value);
}

Expected<double> Flags::GetDouble(const std::string& name, double fallback) const {
  if (!values_.count(name)) return fallback;
  const std::string text = Get(name);
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !std::isfinite(value)) {
    return InvalidArgumentError(name + " = '" + text + "' must be a finite number");
  }
  return value;
}

}  // namespace sandtable::sim
