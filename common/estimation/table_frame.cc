#include "common/estimation/table_frame.h"

namespace sandtable {

Status TableFrameOptions::Check() const { return OkStatus(); }
Expected<TableFrameReport> BuildTableFrame(const Plane&, std::span<const Eigen::Vector3d>,
                                           const Eigen::Vector3d&, const TableFrameOptions&) {
  return InternalError("not implemented yet");
}

}  // namespace sandtable
