#include "sim/site/site_json.h"

#include <fstream>
#include <set>

namespace sandtable::sim {

namespace {

using nlohmann::json;

// Reads fields of one JSON object, remembering the path for messages and which keys were used.
class Reader {
 public:
  Reader(const json& object, std::string path) : object_(object), path_(std::move(path)) {}

  Status Begin() const {
    if (!object_.is_object()) return ParseError(path_ + ": expected an object");
    return OkStatus();
  }
  bool Has(const std::string& key) const { return object_.contains(key); }

  Status Number(const std::string& key, double* out, bool required = false) {
    used_.insert(key);
    if (!object_.contains(key)) return required ? Missing(key) : OkStatus();
    if (!object_[key].is_number()) return ParseError(path_ + "." + key + ": expected a number");
    *out = object_[key].get<double>();
    return OkStatus();
  }
  Status Int(const std::string& key, int* out, bool required = false) {
    used_.insert(key);
    if (!object_.contains(key)) return required ? Missing(key) : OkStatus();
    if (!object_[key].is_number_integer())
      return ParseError(path_ + "." + key + ": expected an integer");
    const int64_t v = object_[key].get<int64_t>();
    if (v < INT32_MIN || v > INT32_MAX) return ParseError(path_ + "." + key + ": out of range");
    *out = static_cast<int>(v);
    return OkStatus();
  }
  Status String(const std::string& key, std::string* out, bool required = false) {
    used_.insert(key);
    if (!object_.contains(key)) return required ? Missing(key) : OkStatus();
    if (!object_[key].is_string()) return ParseError(path_ + "." + key + ": expected a string");
    *out = object_[key].get<std::string>();
    return OkStatus();
  }
  template <int N>
  Status Array(const std::string& key, Eigen::Matrix<double, N, 1>* out, bool required = false) {
    used_.insert(key);
    if (!object_.contains(key)) return required ? Missing(key) : OkStatus();
    const json& a = object_[key];
    if (!a.is_array() || a.size() != N) {
      return ParseError(path_ + "." + key + ": expected an array of " + std::to_string(N) +
                        " numbers");
    }
    for (int i = 0; i < N; ++i) {
      if (!a[i].is_number())
        return ParseError(path_ + "." + key + "[" + std::to_string(i) + "]: expected a number");
      (*out)[i] = a[i].get<double>();
    }
    return OkStatus();
  }
  Expected<Reader> Object(const std::string& key) {
    used_.insert(key);
    if (!object_.contains(key)) return Missing(key);
    Reader r(object_[key], path_ + "." + key);
    ST_RETURN_IF_ERROR(r.Begin());
    return r;
  }
  Status End() const {
    for (auto it = object_.begin(); it != object_.end(); ++it) {
      if (!used_.count(it.key())) return ParseError(path_ + ": unknown key '" + it.key() + "'");
    }
    return OkStatus();
  }
  const std::string& path() const { return path_; }

 private:
  Status Missing(const std::string& key) const {
    return ParseError(path_ + "." + key + ": missing");
  }
  const json& object_;
  std::string path_;
  std::set<std::string> used_;
};

Status ReadRigid(Reader* parent, const std::string& key, Rigid3d* out) {
  Expected<Reader> r = parent->Object(key);
  if (!r.ok()) return r.status();
  ST_RETURN_IF_ERROR(r->Begin());
  Eigen::Vector4d q_xyzw(0, 0, 0, 1);
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  ST_RETURN_IF_ERROR(r->Array<4>("rotation_xyzw", &q_xyzw, true));
  ST_RETURN_IF_ERROR(r->Array<3>("translation_m", &t, true));
  ST_RETURN_IF_ERROR(r->End());
  if (!(q_xyzw.norm() > 1e-9)) return ParseError(r->path() + ".rotation_xyzw: zero quaternion");
  *out = Rigid3d(Eigen::Quaterniond(q_xyzw[3], q_xyzw[0], q_xyzw[1], q_xyzw[2]), t);
  return OkStatus();
}

// Intrinsics: explicit fx/fy/cx/cy, or throw_ratio (+ lens_shift_v).
Status ReadModel(Reader* r, CameraModel* model) {
  int width = 0, height = 0;
  ST_RETURN_IF_ERROR(r->Int("width_px", &width, true));
  ST_RETURN_IF_ERROR(r->Int("height_px", &height, true));
  if (r->Has("throw_ratio")) {
    double throw_ratio = 0, shift = 0;
    ST_RETURN_IF_ERROR(r->Number("throw_ratio", &throw_ratio));
    ST_RETURN_IF_ERROR(r->Number("lens_shift_v", &shift));
    if (!(throw_ratio > 0)) return ParseError(r->path() + ".throw_ratio: must be > 0");
    const BrownDistortion keep = model->distortion;
    *model = CameraModel::FromThrowRatio(width, height, throw_ratio, shift);
    model->distortion = keep;
  } else {
    model->width_px = width;
    model->height_px = height;
    ST_RETURN_IF_ERROR(r->Number("fx_px", &model->fx_px, true));
    ST_RETURN_IF_ERROR(r->Number("fy_px", &model->fy_px, true));
    ST_RETURN_IF_ERROR(r->Number("cx_px", &model->cx_px, true));
    ST_RETURN_IF_ERROR(r->Number("cy_px", &model->cy_px, true));
  }
  Eigen::Matrix<double, 5, 1> d = Eigen::Matrix<double, 5, 1>::Zero();
  ST_RETURN_IF_ERROR(r->Array<5>("distortion_k1_k2_p1_p2_k3", &d));
  model->distortion = BrownDistortion::FromArray(d.data());
  return OkStatus();
}

Status ReadUnit(const json& j, size_t index, UnitSpec* unit) {
  Reader r(j, "units[" + std::to_string(index) + "]");
  ST_RETURN_IF_ERROR(r.Begin());
  int id = -1;
  ST_RETURN_IF_ERROR(r.Int("id", &id, true));
  if (id < 0) return ParseError(r.path() + ".id: must be >= 0");
  unit->id = static_cast<NodeId>(id);
  ST_RETURN_IF_ERROR(r.String("name", &unit->name));
  {
    Expected<Reader> p = r.Object("projector");
    if (!p.ok()) return p.status();
    ProjectorSpec& spec = unit->projector;
    ST_RETURN_IF_ERROR(ReadModel(&*p, &spec.model));
    ST_RETURN_IF_ERROR(ReadRigid(&*p, "table_from_projector", &spec.table_from_projector));
    ST_RETURN_IF_ERROR(p->Number("gamma", &spec.gamma));
    ST_RETURN_IF_ERROR(p->Number("peak_luminance_at_1m_nits", &spec.peak_luminance_at_1m_nits));
    ST_RETURN_IF_ERROR(p->Number("black_level", &spec.black_level));
    ST_RETURN_IF_ERROR(p->Number("focus_distance_m", &spec.focus_distance_m));
    ST_RETURN_IF_ERROR(p->Number("aperture_diameter_m", &spec.aperture_diameter_m));
    ST_RETURN_IF_ERROR(p->End());
  }
  if (r.Has("camera")) {
    Expected<Reader> c = r.Object("camera");
    if (!c.ok()) return c.status();
    CameraSpec spec;
    ST_RETURN_IF_ERROR(ReadModel(&*c, &spec.model));
    ST_RETURN_IF_ERROR(ReadRigid(&*c, "projector_from_camera", &spec.projector_from_camera));
    ST_RETURN_IF_ERROR(c->Number("read_noise_dn", &spec.read_noise_dn));
    ST_RETURN_IF_ERROR(c->Number("exposure_s", &spec.exposure_s));
    ST_RETURN_IF_ERROR(c->Number("saturation_nit_s", &spec.saturation_nit_s));
    ST_RETURN_IF_ERROR(c->Number("full_well_e", &spec.full_well_e));
    ST_RETURN_IF_ERROR(c->Number("gamma", &spec.gamma));
    ST_RETURN_IF_ERROR(c->Int("bit_depth", &spec.bit_depth));
    ST_RETURN_IF_ERROR(c->End());
    unit->camera = spec;
  }
  return r.End();
}

}  // namespace

json RigidToJson(const Rigid3d& t) {
  const Eigen::Quaterniond& q = t.rotation;
  return {{"rotation_xyzw", {q.x(), q.y(), q.z(), q.w()}},
          {"translation_m", {t.translation.x(), t.translation.y(), t.translation.z()}}};
}

json CameraModelToJson(const CameraModel& m) {
  const auto d = m.distortion.ToArray();
  return {{"width_px", m.width_px},
          {"height_px", m.height_px},
          {"fx_px", m.fx_px},
          {"fy_px", m.fy_px},
          {"cx_px", m.cx_px},
          {"cy_px", m.cy_px},
          {"distortion_k1_k2_p1_p2_k3", {d[0], d[1], d[2], d[3], d[4]}}};
}

Expected<Site> SiteFromJson(const json& j) {
  Site site;
  Reader r(j, "site");
  ST_RETURN_IF_ERROR(r.Begin());
  ST_RETURN_IF_ERROR(r.String("name", &site.name));
  ST_RETURN_IF_ERROR(r.Number("ambient_luminance_nits", &site.ambient_luminance_nits));
  {
    Expected<Reader> t = r.Object("table");
    if (!t.ok()) return t.status();
    std::string shape;
    ST_RETURN_IF_ERROR(t->String("shape", &shape, true));
    if (shape == "disc") {
      site.table.is_disc = true;
      ST_RETURN_IF_ERROR(t->Number("diameter_m", &site.table.diameter_m, true));
    } else if (shape == "rectangle") {
      site.table.is_disc = false;
      ST_RETURN_IF_ERROR(t->Array<2>("size_m", &site.table.size_m, true));
    } else {
      return ParseError("site.table.shape: '" + shape + "' is neither 'disc' nor 'rectangle'");
    }
    ST_RETURN_IF_ERROR(t->End());
  }
  if (!j.contains("units") || !j["units"].is_array())
    return ParseError("site.units: expected an array");
  for (size_t i = 0; i < j["units"].size(); ++i) {
    UnitSpec unit;
    ST_RETURN_IF_ERROR(ReadUnit(j["units"][i], i, &unit));
    site.units.push_back(std::move(unit));
  }
  for (auto it = j.begin(); it != j.end(); ++it) {
    static const std::set<std::string> kKnown = {"name", "ambient_luminance_nits", "table",
                                                 "units"};
    if (!kKnown.count(it.key())) return ParseError("site: unknown key '" + it.key() + "'");
  }
  ST_RETURN_IF_ERROR(site.Check());
  return site;
}

json SiteToJson(const Site& site) {
  json units = json::array();
  for (const UnitSpec& u : site.units) {
    json projector = CameraModelToJson(u.projector.model);
    projector["table_from_projector"] = RigidToJson(u.projector.table_from_projector);
    projector["gamma"] = u.projector.gamma;
    projector["peak_luminance_at_1m_nits"] = u.projector.peak_luminance_at_1m_nits;
    projector["black_level"] = u.projector.black_level;
    projector["focus_distance_m"] = u.projector.focus_distance_m;
    projector["aperture_diameter_m"] = u.projector.aperture_diameter_m;
    json unit = {{"id", u.id}, {"name", u.name}, {"projector", projector}};
    if (u.camera) {
      const CameraSpec& c = *u.camera;
      json camera = CameraModelToJson(c.model);
      camera["projector_from_camera"] = RigidToJson(c.projector_from_camera);
      camera["read_noise_dn"] = c.read_noise_dn;
      camera["exposure_s"] = c.exposure_s;
      camera["saturation_nit_s"] = c.saturation_nit_s;
      camera["full_well_e"] = c.full_well_e;
      camera["gamma"] = c.gamma;
      camera["bit_depth"] = c.bit_depth;
      unit["camera"] = camera;
    }
    units.push_back(unit);
  }
  json table = site.table.is_disc
                   ? json{{"shape", "disc"}, {"diameter_m", site.table.diameter_m}}
                   : json{{"shape", "rectangle"},
                          {"size_m", {site.table.size_m.x(), site.table.size_m.y()}}};
  return {{"name", site.name},
          {"ambient_luminance_nits", site.ambient_luminance_nits},
          {"table", table},
          {"units", units}};
}

Expected<Site> LoadSiteFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return IoError(path + ": cannot open site file");
  json j;
  try {
    j = json::parse(in);
  } catch (const json::exception& e) {
    return ParseError(path + ": " + e.what());
  }
  Expected<Site> site = SiteFromJson(j);
  if (!site.ok()) return site.status().WithContext(path);
  return site;
}

Status WriteSiteFile(const Site& site, const std::string& path) {
  std::ofstream out(path);
  if (!out) return IoError(path + ": cannot write site file");
  out << SiteToJson(site).dump(2) << "\n";
  if (!out) return IoError(path + ": write failed");
  return OkStatus();
}

}  // namespace sandtable::sim
