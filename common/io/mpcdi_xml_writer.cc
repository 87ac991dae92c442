// Writing the mpcdi.xml descriptor (mpcdi.h gives the names and why).
#include "common/io/mpcdi_xml.h"

#include <charconv>
#include <string>
#include <utility>

#include <tinyxml2.h>

namespace sandtable::mpcdi_internal {

namespace {

using tinyxml2::XMLElement;

// Shortest text that reads back to the same double (std::to_chars), locale-independent.
std::string Number(double value) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

XMLElement* AddChild(XMLElement* parent, const char* name) {
  return parent->InsertNewChildElement(name);
}

void AddText(XMLElement* parent, const char* name, const std::string& text) {
  AddChild(parent, name)->SetText(text.c_str());
}

void AddNumber(XMLElement* parent, const char* name, double value) {
  AddText(parent, name, Number(value));
}

}  // namespace

std::string WarpFileName(const std::string& region_id) {
  return "GeometryWarpFile-" + region_id + ".pfm";
}
std::string AlphaFileName(const std::string& region_id) { return "AlphaMap-" + region_id + ".png"; }
std::string BetaFileName(const std::string& region_id) { return "BetaMap-" + region_id + ".png"; }

std::string EncodeMpcdiXml(const MpcdiSite& site, const std::string& date) {
  tinyxml2::XMLDocument doc;
  doc.InsertEndChild(doc.NewDeclaration("xml version=\"1.0\" encoding=\"utf-8\""));
  XMLElement* root = doc.NewElement("MPCDI");
  doc.InsertEndChild(root);
  root->SetAttribute("profile", site.profile.c_str());
  root->SetAttribute("level", site.level);
  root->SetAttribute("date", date.c_str());
  root->SetAttribute("version", "1.0");

  XMLElement* buffer = AddChild(AddChild(root, "display"), "buffer");
  buffer->SetAttribute("id", site.buffer_id.c_str());
  if (site.buffer_x_resolution_px > 0)
    buffer->SetAttribute("Xresolution", site.buffer_x_resolution_px);
  if (site.buffer_y_resolution_px > 0)
    buffer->SetAttribute("Yresolution", site.buffer_y_resolution_px);
  for (const MpcdiRegion& region : site.regions) {
    XMLElement* e = AddChild(buffer, "region");
    e->SetAttribute("id", region.id.c_str());
    e->SetAttribute("Xresolution", region.x_resolution_px);
    e->SetAttribute("Yresolution", region.y_resolution_px);
    e->SetAttribute("x", Number(region.x).c_str());
    e->SetAttribute("y", Number(region.y).c_str());
    e->SetAttribute("xsize", Number(region.x_size).c_str());
    e->SetAttribute("ysize", Number(region.y_size).c_str());
    if (region.frustum) {
      const MpcdiFrustum& f = *region.frustum;
      XMLElement* fe = AddChild(e, "frustum");
      AddNumber(fe, "yaw", f.yaw_deg);
      AddNumber(fe, "pitch", f.pitch_deg);
      AddNumber(fe, "roll", f.roll_deg);
      AddNumber(fe, "rightAngle", f.right_angle_deg);
      AddNumber(fe, "leftAngle", f.left_angle_deg);
      AddNumber(fe, "upAngle", f.up_angle_deg);
      AddNumber(fe, "downAngle", f.down_angle_deg);
    }
    if (region.coordinate_frame) {
      const MpcdiCoordinateFrame& c = *region.coordinate_frame;
      XMLElement* ce = AddChild(e, "coordinateFrame");
      const std::pair<const char*, const Eigen::Vector3d*> vectors[] = {{"pos", &c.position},
                                                                        {"yaw", &c.yaw_axis},
                                                                        {"pitch", &c.pitch_axis},
                                                                        {"roll", &c.roll_axis}};
      for (const auto& [prefix, v] : vectors) {
        for (int k = 0; k < 3; ++k) {
          AddNumber(ce, (std::string(prefix) + "xyz"[k]).c_str(), (*v)[k]);
        }
      }
    }
  }

  XMLElement* files = AddChild(root, "files");
  for (const MpcdiRegion& region : site.regions) {
    XMLElement* fileset = AddChild(files, "fileset");
    fileset->SetAttribute("region", region.id.c_str());
    const MpcdiWarp& warp = *region.warp;
    XMLElement* we = AddChild(fileset, "geometryWarpFile");
    AddText(we, "path", WarpFileName(region.id));
    if (!warp.geometric_unit.empty()) AddText(we, "geometricUnit", warp.geometric_unit);
    if (!warp.interpolation.empty()) AddText(we, "interpolation", warp.interpolation);
    if (!warp.origin_of_3d_data.empty()) AddText(we, "originOf3DData", warp.origin_of_3d_data);
    XMLElement* ae = AddChild(fileset, "alphaMap");
    AddText(ae, "path", AlphaFileName(region.id));
    AddText(ae, "componentDepth", "1");
    AddText(ae, "bitDepth", "8");
    AddNumber(ae, "gammaEmbedded", region.alpha->gamma_embedded);
    if (region.beta) {
      XMLElement* be = AddChild(fileset, "betaMap");
      AddText(be, "path", BetaFileName(region.id));
      AddText(be, "componentDepth", "1");
      AddText(be, "bitDepth", "8");
    }
  }
  tinyxml2::XMLPrinter printer;
  doc.Print(&printer);
  return printer.CStr();
}

}  // namespace sandtable::mpcdi_internal
