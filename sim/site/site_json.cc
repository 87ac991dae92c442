#include "sim/site/site_json.h"

#include "common/io/json_reader.h"

namespace sandtable::sim {

namespace {

using io::ObjectReader;
using io::Presence;
using nlohmann::json;

constexpr int kMaxId = 1 << 30;

Status ReadProjector(ObjectReader* unit, ProjectorSpec* spec) {
  Expected<ObjectReader> p = unit->Object("projector");
  if (!p.ok()) return p.status();
  ST_RETURN_IF_ERROR(io::ReadCameraModelFields(&*p, &spec->model));
  Expected<Rigid3d> table_from_projector = io::ReadRigid(&*p, "table_from_projector");
  if (!table_from_projector.ok()) return table_from_projector.status();
  spec->table_from_projector = *table_from_projector;
  ST_RETURN_IF_ERROR(p->Number("gamma", &spec->gamma, Presence::kOptional));
  ST_RETURN_IF_ERROR(p->Number("peak_luminance_at_1m_nits", &spec->peak_luminance_at_1m_nits,
                               Presence::kOptional));
  ST_RETURN_IF_ERROR(p->Number("black_level", &spec->black_level, Presence::kOptional));
  ST_RETURN_IF_ERROR(p->Number("focus_distance_m", &spec->focus_distance_m, Presence::kOptional));
  ST_RETURN_IF_ERROR(
      p->Number("aperture_diameter_m", &spec->aperture_diameter_m, Presence::kOptional));
  return p->End();
}

Status ReadCamera(ObjectReader* unit, CameraSpec* spec) {
  Expected<ObjectReader> c = unit->Object("camera");
  if (!c.ok()) return c.status();
  ST_RETURN_IF_ERROR(io::ReadCameraModelFields(&*c, &spec->model));
  Expected<Rigid3d> projector_from_camera = io::ReadRigid(&*c, "projector_from_camera");
  if (!projector_from_camera.ok()) return projector_from_camera.status();
  spec->projector_from_camera = *projector_from_camera;
  ST_RETURN_IF_ERROR(c->Number("read_noise_dn", &spec->read_noise_dn, Presence::kOptional));
  ST_RETURN_IF_ERROR(c->Number("exposure_s", &spec->exposure_s, Presence::kOptional));
  ST_RETURN_IF_ERROR(c->Number("saturation_nit_s", &spec->saturation_nit_s, Presence::kOptional));
  ST_RETURN_IF_ERROR(c->Number("full_well_e", &spec->full_well_e, Presence::kOptional));
  ST_RETURN_IF_ERROR(c->Number("gamma", &spec->gamma, Presence::kOptional));
  ST_RETURN_IF_ERROR(c->Int("bit_depth", 1, 16, &spec->bit_depth, Presence::kOptional));
  return c->End();
}

Status ReadTiming(ObjectReader* unit, DeviceTiming* t) {
  Expected<ObjectReader> r = unit->Object("timing");
  if (!r.ok()) return r.status();
  ST_RETURN_IF_ERROR(r->Number("refresh_hz", &t->refresh_hz, Presence::kOptional));
  ST_RETURN_IF_ERROR(r->Int("lag_frames", 0, 10, &t->lag_frames, Presence::kOptional));
  ST_RETURN_IF_ERROR(r->Number("camera_fps", &t->camera_fps, Presence::kOptional));
  ST_RETURN_IF_ERROR(r->Number("camera_latency_s", &t->camera_latency_s, Presence::kOptional));
  ST_RETURN_IF_ERROR(r->Int("queue_frames", 1, 16, &t->queue_frames, Presence::kOptional));
  ST_RETURN_IF_ERROR(r->Number("drop_rate", &t->drop_rate, Presence::kOptional));
  ST_RETURN_IF_ERROR(r->Number("repeat_rate", &t->repeat_rate, Presence::kOptional));
  ST_RETURN_IF_ERROR(
      r->Number("auto_exposure_drift", &t->auto_exposure_drift, Presence::kOptional));
  ST_RETURN_IF_ERROR(
      r->Number("auto_exposure_period_s", &t->auto_exposure_period_s, Presence::kOptional));
  return r->End();
}

json TimingToJson(const DeviceTiming& t) {
  return {{"refresh_hz", t.refresh_hz},
          {"lag_frames", t.lag_frames},
          {"camera_fps", t.camera_fps},
          {"camera_latency_s", t.camera_latency_s},
          {"queue_frames", t.queue_frames},
          {"drop_rate", t.drop_rate},
          {"repeat_rate", t.repeat_rate},
          {"auto_exposure_drift", t.auto_exposure_drift},
          {"auto_exposure_period_s", t.auto_exposure_period_s}};
}

Status ReadUnit(const json& j, const std::string& where, UnitSpec* unit) {
  ObjectReader r(j, where);
  ST_RETURN_IF_ERROR(r.Begin());
  int id = -1;
  ST_RETURN_IF_ERROR(r.Int("id", 0, kMaxId, &id));
  unit->id = static_cast<NodeId>(id);
  ST_RETURN_IF_ERROR(r.String("name", &unit->name, Presence::kOptional));
  ST_RETURN_IF_ERROR(ReadProjector(&r, &unit->projector));
  if (r.Has("camera")) {
    CameraSpec spec;
    ST_RETURN_IF_ERROR(ReadCamera(&r, &spec));
    unit->camera = spec;
  }
  if (r.Has("timing")) ST_RETURN_IF_ERROR(ReadTiming(&r, &unit->timing));
  return r.End();
}

Status ReadTable(ObjectReader* site, TableSpec* table) {
  Expected<ObjectReader> t = site->Object("table");
  if (!t.ok()) return t.status();
  std::string shape;
  ST_RETURN_IF_ERROR(t->String("shape", &shape));
  if (shape == "disc") {
    table->is_disc = true;
    ST_RETURN_IF_ERROR(t->Number("diameter_m", &table->diameter_m));
  } else if (shape == "rectangle") {
    table->is_disc = false;
    ST_RETURN_IF_ERROR(t->Numbers("size_m", std::span<double>(table->size_m.data(), 2)));
  } else {
    return ParseError(t->Field("shape") + " = '" + shape + "' is neither 'disc' nor 'rectangle'");
  }
  return t->End();
}

}  // namespace

Expected<Site> SiteFromJson(const json& j) {
  Site site;
  ObjectReader r(j, "site");
  ST_RETURN_IF_ERROR(r.Begin());
  // Files written before sites carried format/version have neither.
  if (r.Has("format") || r.Has("version")) {
    Expected<int> version = io::ReadFormatVersion(&r, kSiteFormat, kSiteVersion, kSiteVersion);
    if (!version.ok()) return version.status();
  }
  ST_RETURN_IF_ERROR(r.String("name", &site.name, Presence::kOptional));
  ST_RETURN_IF_ERROR(
      r.Number("ambient_luminance_nits", &site.ambient_luminance_nits, Presence::kOptional));
  ST_RETURN_IF_ERROR(ReadTable(&r, &site.table));
  const json* units = r.Find("units");
  if (units == nullptr || !units->is_array()) {
    return ParseError(r.Field("units") + " must be an array of units");
  }
  if (units->size() > kMaxSiteUnits) {  // before reading (and allocating) any unit
    return InvalidArgumentError(
        r.Field("units") + ": " + std::to_string(units->size()) +
        " units, more than kMaxSiteUnits = " + std::to_string(kMaxSiteUnits));
  }
  for (size_t i = 0; i < units->size(); ++i) {
    UnitSpec unit;
    ST_RETURN_IF_ERROR(ReadUnit((*units)[i], io::JoinIndex(r.Field("units"), i), &unit));
    site.units.push_back(std::move(unit));
  }
  ST_RETURN_IF_ERROR(r.End());
  ST_RETURN_IF_ERROR(site.Check());
  return site;
}

json SiteToJson(const Site& site) {
  json units = json::array();
  for (const UnitSpec& u : site.units) {
    json projector = io::CameraModelToJson(u.projector.model);
    projector["table_from_projector"] = io::RigidToJson(u.projector.table_from_projector);
    projector["gamma"] = u.projector.gamma;
    projector["peak_luminance_at_1m_nits"] = u.projector.peak_luminance_at_1m_nits;
    projector["black_level"] = u.projector.black_level;
    projector["focus_distance_m"] = u.projector.focus_distance_m;
    projector["aperture_diameter_m"] = u.projector.aperture_diameter_m;
    json unit = {{"id", u.id}, {"name", u.name}, {"projector", projector}};
    if (u.camera) {
      const CameraSpec& c = *u.camera;
      json camera = io::CameraModelToJson(c.model);
      camera["projector_from_camera"] = io::RigidToJson(c.projector_from_camera);
      camera["read_noise_dn"] = c.read_noise_dn;
      camera["exposure_s"] = c.exposure_s;
      camera["saturation_nit_s"] = c.saturation_nit_s;
      camera["full_well_e"] = c.full_well_e;
      camera["gamma"] = c.gamma;
      camera["bit_depth"] = c.bit_depth;
      unit["camera"] = camera;
    }
    if (u.timing != DeviceTiming{}) unit["timing"] = TimingToJson(u.timing);
    units.push_back(unit);
  }
  json table = site.table.is_disc
                   ? json{{"shape", "disc"}, {"diameter_m", site.table.diameter_m}}
                   : json{{"shape", "rectangle"},
                          {"size_m", {site.table.size_m.x(), site.table.size_m.y()}}};
  return {{"format", kSiteFormat}, {"version", kSiteVersion},
          {"name", site.name},     {"ambient_luminance_nits", site.ambient_luminance_nits},
          {"table", table},        {"units", units}};
}

Expected<Site> LoadSiteFile(const std::string& path) {
  Expected<json> j = io::ReadJsonFile(path);
  if (!j.ok()) return j.status();
  Expected<Site> site = SiteFromJson(*j);
  if (!site.ok()) return site.status().WithContext(path);
  return site;
}

Status WriteSiteFile(const Site& site, const std::string& path) {
  return io::WriteJsonFile(SiteToJson(site), path);
}

}  // namespace sandtable::sim
