#include "common/io/mpcdi_xml.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <initializer_list>
#include <optional>
#include <set>

#include <tinyxml2.h>

namespace sandtable::mpcdi_internal {

namespace {

using tinyxml2::XMLAttribute;
using tinyxml2::XMLElement;

char Lower(char c) { return (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c; }

// The standard makes tag and attribute names case-insensitive (MPCDI 1a 3.5.2).
bool NameIs(const char* name, std::string_view wanted) {
  const std::string_view n(name == nullptr ? "" : name);
  return n.size() == wanted.size() &&
         std::equal(n.begin(), n.end(), wanted.begin(),
                    [](char a, char b) { return Lower(a) == Lower(b); });
}

std::string_view Trim(std::string_view s) {
  const auto space = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; };
  while (!s.empty() && space(s.front())) s.remove_prefix(1);
  while (!s.empty() && space(s.back())) s.remove_suffix(1);
  return s;
}

// A value from a fixed list, matched case-insensitively, returned in the list's spelling.
std::optional<std::string> Canonical(std::string_view value,
                                     std::initializer_list<const char*> names) {
  for (const char* name : names) {
    if (NameIs(name, value)) return std::string(name);
  }
  return std::nullopt;
}

bool IsPlainFileName(std::string_view name) {
  return !name.empty() && name.size() <= 255 && name != "." && name != ".." &&
         name.find_first_of(std::string_view("/\\\0", 3)) == std::string_view::npos;
}

const XMLAttribute* AttributeNamed(const XMLElement* e, std::string_view name) {
  for (const XMLAttribute* a = e->FirstAttribute(); a != nullptr; a = a->Next()) {
    if (NameIs(a->Name(), name)) return a;
  }
  return nullptr;
}

// Where an element is: "MPCDI/display/buffer[id=0]/region[id=Rear]/frustum (line 7)".
std::string Describe(const XMLElement* e) {
  std::vector<std::string> parts;
  for (const XMLElement* at = e; at != nullptr;
       at = at->Parent() != nullptr ? at->Parent()->ToElement() : nullptr) {
    std::string part = at->Name();
    for (const char* key : {"id", "region"}) {
      if (const XMLAttribute* a = AttributeNamed(at, key)) {
        part += std::string("[") + key + "=" + a->Value() + "]";
        break;
      }
    }
    parts.push_back(std::move(part));
  }
  std::string path;
  for (auto it = parts.rbegin(); it != parts.rend(); ++it) {
    if (!path.empty()) path += "/";
    path += *it;
  }
  return path + " (line " + std::to_string(e->GetLineNum()) + ")";
}

class Reader {
 public:
  explicit Reader(const std::string& source) : source_(source) {}

  Status Error(StatusCode code, const XMLElement* e, const std::string& message) const {
    return Status(code, source_ + ": " + Describe(e) + ": " + message);
  }

  // The one child named `name` (nullptr when none); two of them are an error.
  Expected<const XMLElement*> OptionalChild(const XMLElement* e, std::string_view name) const {
    const XMLElement* found = nullptr;
    for (const XMLElement* c = e->FirstChildElement(); c != nullptr; c = c->NextSiblingElement()) {
      if (!NameIs(c->Name(), name)) continue;
      if (found != nullptr) {
        return Error(StatusCode::kParseError, c, "<" + std::string(name) + "> given twice");
      }
      found = c;
    }
    return found;
  }

  Expected<const XMLElement*> Child(const XMLElement* e, std::string_view name) const {
    Expected<const XMLElement*> child = OptionalChild(e, name);
    if (child.ok() && *child == nullptr) {
      return Error(StatusCode::kParseError, e, "missing <" + std::string(name) + ">");
    }
    return child;
  }

  std::vector<const XMLElement*> Children(const XMLElement* e, std::string_view name) const {
    std::vector<const XMLElement*> out;
    for (const XMLElement* c = e->FirstChildElement(); c != nullptr; c = c->NextSiblingElement()) {
      if (NameIs(c->Name(), name)) out.push_back(c);
    }
    return out;
  }

  Expected<std::optional<std::string>> OptionalAttribute(const XMLElement* e,
                                                         std::string_view name) const {
    const XMLAttribute* found = nullptr;
    for (const XMLAttribute* a = e->FirstAttribute(); a != nullptr; a = a->Next()) {
      if (!NameIs(a->Name(), name)) continue;
      if (found != nullptr) {
        return Error(
            StatusCode::kParseError, e,
            "attribute " + std::string(name) + " given twice (names are case-insensitive)");
      }
      found = a;
    }
    if (found == nullptr) return std::optional<std::string>();
    return std::optional<std::string>(std::string(Trim(found->Value())));
  }

  Expected<std::string> Attribute(const XMLElement* e, std::string_view name) const {
    Expected<std::optional<std::string>> value = OptionalAttribute(e, name);
    if (!value.ok()) return value.status();
    if (!value->has_value()) {
      return Error(StatusCode::kParseError, e, "attribute " + std::string(name) + " missing");
    }
    return **value;
  }

  Expected<double> Double(const XMLElement* e, std::string_view text, std::string_view what) const {
    double value = 0.0;
    const auto result = std::from_chars(text.data(), text.data() + text.size(), value);
    if (text.empty() || result.ec != std::errc() || result.ptr != text.data() + text.size() ||
        !std::isfinite(value)) {
      return Error(StatusCode::kParseError, e,
                   std::string(what) + " = \"" + std::string(text) + "\" is not a finite number");
    }
    return value;
  }

  Expected<int> Int(const XMLElement* e, std::string_view text, std::string_view what, int min,
                    int max) const {
    int value = 0;
    const auto result = std::from_chars(text.data(), text.data() + text.size(), value);
    if (text.empty() || result.ec != std::errc() || result.ptr != text.data() + text.size()) {
      return Error(StatusCode::kParseError, e,
                   std::string(what) + " = \"" + std::string(text) + "\" is not an integer");
    }
    if (value < min || value > max) {
      return Error(StatusCode::kInvalidArgument, e,
                   std::string(what) + " = " + std::to_string(value) + " outside [" +
                       std::to_string(min) + ", " + std::to_string(max) + "]");
    }
    return value;
  }

  Expected<std::string> ChildText(const XMLElement* e, std::string_view name) const {
    Expected<const XMLElement*> child = Child(e, name);
    if (!child.ok()) return child.status();
    const char* text = (*child)->GetText();
    return std::string(Trim(text == nullptr ? "" : text));
  }

  Expected<double> ChildDouble(const XMLElement* e, std::string_view name) const {
    Expected<std::string> text = ChildText(e, name);
    if (!text.ok()) return text.status();
    return Double(e, *text, "<" + std::string(name) + ">");
  }

  Expected<int> ChildInt(const XMLElement* e, std::string_view name, int min, int max) const {
    Expected<std::string> text = ChildText(e, name);
    if (!text.ok()) return text.status();
    return Int(e, *text, "<" + std::string(name) + ">", min, max);
  }

  Expected<double> AttributeDouble(const XMLElement* e, std::string_view name) const {
    Expected<std::string> text = Attribute(e, name);
    if (!text.ok()) return text.status();
    return Double(e, *text, "attribute " + std::string(name));
  }

  Expected<int> AttributeInt(const XMLElement* e, std::string_view name, int min, int max) const {
    Expected<std::string> text = Attribute(e, name);
    if (!text.ok()) return text.status();
    return Int(e, *text, "attribute " + std::string(name), min, max);
  }

  // A child's text that must be one of `names` (case-insensitive); nullopt when the child is
  // absent and not `required`.
  Expected<std::optional<std::string>> ChildEnum(const XMLElement* e, std::string_view name,
                                                 std::initializer_list<const char*> names,
                                                 bool required) const {
    Expected<const XMLElement*> child = OptionalChild(e, name);
    if (!child.ok()) return child.status();
    if (*child == nullptr) {
      if (required) return Error(StatusCode::kParseError, e, "missing <" + std::string(name) + ">");
      return std::optional<std::string>();
    }
    const char* raw = (*child)->GetText();
    const std::string_view text = Trim(raw == nullptr ? "" : raw);
    std::optional<std::string> value = Canonical(text, names);
    if (!value) {
      std::string list;
      for (const char* n : names) list += (list.empty() ? "" : ", ") + std::string(n);
      return Error(StatusCode::kInvalidArgument, *child,
                   "\"" + std::string(text) + "\" is not one of " + list);
    }
    return value;
  }

  const std::string& source() const { return source_; }

 private:
  const std::string& source_;
};

// Assigns `expr` (an Expected) to `target` or returns its error.
#define MPCDI_ASSIGN(target, expr)                        \
  do {                                                    \
    auto mpcdi_value_ = (expr);                           \
    if (!mpcdi_value_.ok()) return mpcdi_value_.status(); \
    target = std::move(*mpcdi_value_);                    \
  } while (false)

Status ReadFrustum(const Reader& r, const XMLElement* e, MpcdiFrustum* f) {
  MPCDI_ASSIGN(f->yaw_deg, r.ChildDouble(e, "yaw"));
  MPCDI_ASSIGN(f->pitch_deg, r.ChildDouble(e, "pitch"));
  MPCDI_ASSIGN(f->roll_deg, r.ChildDouble(e, "roll"));
  MPCDI_ASSIGN(f->right_angle_deg, r.ChildDouble(e, "rightAngle"));
  MPCDI_ASSIGN(f->left_angle_deg, r.ChildDouble(e, "leftAngle"));
  MPCDI_ASSIGN(f->up_angle_deg, r.ChildDouble(e, "upAngle"));
  MPCDI_ASSIGN(f->down_angle_deg, r.ChildDouble(e, "downAngle"));
  return OkStatus();
}

Status ReadVector(const Reader& r, const XMLElement* e, const std::string& prefix,
                  Eigen::Vector3d* v) {
  MPCDI_ASSIGN((*v)[0], r.ChildDouble(e, prefix + "x"));
  MPCDI_ASSIGN((*v)[1], r.ChildDouble(e, prefix + "y"));
  MPCDI_ASSIGN((*v)[2], r.ChildDouble(e, prefix + "z"));
  return OkStatus();
}

Status ReadCoordinateFrame(const Reader& r, const XMLElement* e, MpcdiCoordinateFrame* c) {
  ST_RETURN_IF_ERROR(ReadVector(r, e, "pos", &c->position));
  ST_RETURN_IF_ERROR(ReadVector(r, e, "yaw", &c->yaw_axis));
  ST_RETURN_IF_ERROR(ReadVector(r, e, "pitch", &c->pitch_axis));
  ST_RETURN_IF_ERROR(ReadVector(r, e, "roll", &c->roll_axis));
  return OkStatus();
}

Status ReadRegion(const Reader& r, const XMLElement* e, const std::string& profile,
                  MpcdiRegion* region) {
  MPCDI_ASSIGN(region->id, r.Attribute(e, "id"));
  if (region->id.empty()) return r.Error(StatusCode::kParseError, e, "attribute id is empty");
  MPCDI_ASSIGN(region->x_resolution_px,
               r.AttributeInt(e, "Xresolution", 1, kMaxMpcdiResolution_px));
  MPCDI_ASSIGN(region->y_resolution_px,
               r.AttributeInt(e, "Yresolution", 1, kMaxMpcdiResolution_px));
  MPCDI_ASSIGN(region->x, r.AttributeDouble(e, "x"));
  MPCDI_ASSIGN(region->y, r.AttributeDouble(e, "y"));
  MPCDI_ASSIGN(region->x_size, r.AttributeDouble(e, "xsize"));
  MPCDI_ASSIGN(region->y_size, r.AttributeDouble(e, "ysize"));
  const XMLElement* frustum = nullptr;
  MPCDI_ASSIGN(frustum, r.OptionalChild(e, "frustum"));
  if (frustum != nullptr) {
    region->frustum.emplace();
    ST_RETURN_IF_ERROR(ReadFrustum(r, frustum, &*region->frustum));
  } else if (profile == "3d" || profile == "sl") {
    return r.Error(StatusCode::kParseError, e,
                   "missing <frustum> (required for profile " + profile + ")");
  }
  const XMLElement* frame = nullptr;
  MPCDI_ASSIGN(frame, r.OptionalChild(e, "coordinateFrame"));
  if (frame != nullptr) {
    region->coordinate_frame.emplace();
    ST_RETURN_IF_ERROR(ReadCoordinateFrame(r, frame, &*region->coordinate_frame));
  } else if (profile == "sl") {
    return r.Error(StatusCode::kParseError, e,
                   "missing <coordinateFrame> (required for profile sl)");
  }
  return OkStatus();
}

Expected<std::string> FilePath(const Reader& r, const XMLElement* e) {
  Expected<std::string> path = r.ChildText(e, "path");
  if (!path.ok()) return path.status();
  if (!IsPlainFileName(*path)) {
    return r.Error(StatusCode::kInvalidArgument, e,
                   "path \"" + *path + "\" is not a plain file name (MPCDI 3.3: no folders)");
  }
  return path;
}

// An <alphaMap> or <betaMap>; an empty element (as SGCT writes <alphaMap />) is no map.
Status ReadBlendMap(const Reader& r, const XMLElement* e, size_t region, bool alpha,
                    ParsedMpcdiXml* parsed) {
  if (e->FirstChildElement() == nullptr) return OkStatus();
  MpcdiFileRequest request;
  request.region = region;
  request.kind = alpha ? MpcdiFileRequest::Kind::kAlpha : MpcdiFileRequest::Kind::kBeta;
  request.element = Describe(e);
  MPCDI_ASSIGN(request.path, FilePath(r, e));
  MPCDI_ASSIGN(request.component_depth, r.ChildInt(e, "componentDepth", 1, 4));
  MPCDI_ASSIGN(request.bit_depth, r.ChildInt(e, "bitDepth", 1, 64));
  MpcdiBlendMap map;
  if (alpha) {
    MPCDI_ASSIGN(map.gamma_embedded, r.ChildDouble(e, "gammaEmbedded"));
    if (map.gamma_embedded <= 0.0) {
      return r.Error(StatusCode::kInvalidArgument, e, "<gammaEmbedded> must be > 0");
    }
  }
  (alpha ? parsed->site.regions[region].alpha : parsed->site.regions[region].beta) = map;
  parsed->files.push_back(std::move(request));
  return OkStatus();
}

Status ReadFileset(const Reader& r, const XMLElement* e, std::set<size_t>* seen,
                   ParsedMpcdiXml* parsed) {
  std::string region_id;
  MPCDI_ASSIGN(region_id, r.Attribute(e, "region"));
  size_t region = parsed->site.regions.size();
  for (size_t i = 0; i < parsed->site.regions.size(); ++i) {
    if (parsed->site.regions[i].id == region_id) region = i;
  }
  if (region == parsed->site.regions.size()) {
    return r.Error(StatusCode::kParseError, e,
                   "attribute region = \"" + region_id + "\" names no region of the display");
  }
  if (!seen->insert(region).second) {
    return r.Error(StatusCode::kParseError, e, "a second fileset for region \"" + region_id + "\"");
  }
  const std::string& profile = parsed->site.profile;
  const bool needs_3d_tags = profile == "sl" || profile == "a3";
  const XMLElement* warp_element = nullptr;
  MPCDI_ASSIGN(warp_element, r.Child(e, "geometryWarpFile"));
  MpcdiWarp warp;
  std::optional<std::string> value;
  MPCDI_ASSIGN(value, r.ChildEnum(warp_element, "interpolation",
                                  {"linear", "keystone", "smooth", "unknown"}, false));
  warp.interpolation = value.value_or("");
  MPCDI_ASSIGN(value,
               r.ChildEnum(warp_element, "geometricUnit",
                           {"mm", "cm", "dm", "m", "in", "ft", "yd", "unknown"}, needs_3d_tags));
  warp.geometric_unit = value.value_or("");
  MPCDI_ASSIGN(value, r.ChildEnum(warp_element, "originOf3DData",
                                  {"centerOfMass", "idealEyePoint", "floorCenter", "unknown"},
                                  needs_3d_tags));
  warp.origin_of_3d_data = value.value_or("");
  MpcdiFileRequest request;
  request.region = region;
  request.kind = MpcdiFileRequest::Kind::kWarp;
  request.element = Describe(warp_element);
  MPCDI_ASSIGN(request.path, FilePath(r, warp_element));
  parsed->site.regions[region].warp = std::move(warp);
  parsed->files.push_back(std::move(request));

  const XMLElement* map = nullptr;
  MPCDI_ASSIGN(map, r.OptionalChild(e, "alphaMap"));
  if (map != nullptr) ST_RETURN_IF_ERROR(ReadBlendMap(r, map, region, true, parsed));
  MPCDI_ASSIGN(map, r.OptionalChild(e, "betaMap"));
  if (map != nullptr) ST_RETURN_IF_ERROR(ReadBlendMap(r, map, region, false, parsed));
  return OkStatus();
}

}  // namespace

Expected<ParsedMpcdiXml> ParseMpcdiXml(std::string_view xml, const std::string& source) {
  tinyxml2::XMLDocument doc;
  if (doc.Parse(xml.data(), xml.size()) != tinyxml2::XML_SUCCESS) {
    const char* detail = doc.ErrorStr();
    return ParseError(source + ": not well-formed XML (line " + std::to_string(doc.ErrorLineNum()) +
                      "): " + (detail != nullptr ? detail : "tinyxml2 error"));
  }
  const XMLElement* root = doc.RootElement();
  if (root == nullptr || !NameIs(root->Name(), "MPCDI")) {
    return ParseError(source + ": the root element is <" +
                      (root != nullptr ? root->Name() : std::string()) + ">, not <MPCDI>");
  }
  const Reader r(source);
  ParsedMpcdiXml parsed;
  MpcdiSite& site = parsed.site;

  std::string profile;
  MPCDI_ASSIGN(profile, r.Attribute(root, "profile"));
  const std::optional<std::string> canonical_profile = Canonical(profile, {"2d", "3d", "a3", "sl"});
  if (!canonical_profile) {
    return r.Error(StatusCode::kInvalidArgument, root,
                   "profile = \"" + profile + "\" is not 2d, 3d, a3 or sl");
  }
  site.profile = *canonical_profile;
  MPCDI_ASSIGN(site.version, r.Attribute(root, "version"));
  if (site.version.empty() || (site.version[0] != '1' && site.version[0] != '2') ||
      (site.version.size() > 1 && site.version[1] != '.')) {
    return r.Error(StatusCode::kInvalidArgument, root,
                   "version = \"" + site.version + "\" is not supported (1.x or 2.x)");
  }
  std::optional<std::string> level_text;
  MPCDI_ASSIGN(level_text, r.OptionalAttribute(root, "level"));
  const char* level_name = "level";
  if (!level_text) {
    MPCDI_ASSIGN(level_text, r.OptionalAttribute(root, "geometry"));
    level_name = "geometry";
  }
  if (!level_text) {
    return r.Error(StatusCode::kParseError, root,
                   "attribute level (MPCDI 1.x) or geometry (2.x) missing");
  }
  MPCDI_ASSIGN(site.level, r.Int(root, *level_text, std::string("attribute ") + level_name, 1, 4));
  std::optional<std::string> date;
  MPCDI_ASSIGN(date, r.OptionalAttribute(root, "date"));
  site.date = date.value_or("");

  const XMLElement* display = nullptr;
  MPCDI_ASSIGN(display, r.Child(root, "display"));
  const std::vector<const XMLElement*> buffers = r.Children(display, "buffer");
  if (buffers.empty()) return r.Error(StatusCode::kParseError, display, "no <buffer>");
  if (buffers.size() > 1) {
    return r.Error(StatusCode::kInvalidArgument, display,
                   std::to_string(buffers.size()) + " buffers; this reader supports one");
  }
  const XMLElement* buffer = buffers.front();
  MPCDI_ASSIGN(site.buffer_id, r.Attribute(buffer, "id"));
  for (const auto& [name, target] : {std::pair{"Xresolution", &site.buffer_x_resolution_px},
                                     std::pair{"Yresolution", &site.buffer_y_resolution_px}}) {
    std::optional<std::string> text;
    MPCDI_ASSIGN(text, r.OptionalAttribute(buffer, name));
    if (text) {
      MPCDI_ASSIGN(*target, r.Int(buffer, *text, std::string("attribute ") + name, 1,
                                  kMaxMpcdiResolution_px));
    }
  }
  const std::vector<const XMLElement*> regions = r.Children(buffer, "region");
  if (regions.empty()) return r.Error(StatusCode::kParseError, buffer, "no <region>");
  if (regions.size() > static_cast<size_t>(kMaxMpcdiRegions)) {
    return r.Error(StatusCode::kInvalidArgument, buffer,
                   std::to_string(regions.size()) + " regions, over kMaxMpcdiRegions");
  }
  std::set<std::string> ids;
  for (const XMLElement* e : regions) {
    MpcdiRegion region;
    ST_RETURN_IF_ERROR(ReadRegion(r, e, site.profile, &region));
    if (!ids.insert(region.id).second) {
      return r.Error(StatusCode::kParseError, e, "region id \"" + region.id + "\" given twice");
    }
    site.regions.push_back(std::move(region));
  }

  const XMLElement* files = nullptr;
  MPCDI_ASSIGN(files, r.OptionalChild(root, "files"));
  if (files != nullptr) {
    std::set<size_t> seen;
    for (const XMLElement* e : r.Children(files, "fileset")) {
      ST_RETURN_IF_ERROR(ReadFileset(r, e, &seen, &parsed));
    }
  }
  return parsed;
}

#undef MPCDI_ASSIGN

}  // namespace sandtable::mpcdi_internal
