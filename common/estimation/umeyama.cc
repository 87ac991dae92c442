#include "common/estimation/umeyama.h"

namespace sandtable {

Status UmeyamaOptions::Check() const { return OkStatus(); }
Expected<RigidFitReport> FitRigidUmeyama(std::span<const Eigen::Vector3d>,
                                         std::span<const Eigen::Vector3d>, const UmeyamaOptions&) {
  return InternalError("not implemented yet");
}
Expected<SimilarityFitReport> FitSimilarityUmeyama(std::span<const Eigen::Vector3d>,
                                                   std::span<const Eigen::Vector3d>,
                                                   const UmeyamaOptions&) {
  return InternalError("not implemented yet");
}

}  // namespace sandtable
