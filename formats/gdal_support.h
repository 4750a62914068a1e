#pragma once
// Small helpers shared by the GDAL-based readers (formats/dem, formats/vector).

#include <cpl_error.h>
#include <gdal_priv.h>

#include <algorithm>
#include <memory>
#include <string>

namespace terratiles {

// GDAL reports errors through a global handler; collect the last message quietly and put
// it into our own one-line error instead of letting GDAL print to stderr.
class GdalErrorCapture {
 public:
  GdalErrorCapture() {
    CPLPushErrorHandler(CPLQuietErrorHandler);
    CPLErrorReset();
  }
  ~GdalErrorCapture() { CPLPopErrorHandler(); }
  GdalErrorCapture(const GdalErrorCapture&) = delete;
  GdalErrorCapture& operator=(const GdalErrorCapture&) = delete;
  std::string lastMessage() const {
    std::string message = CPLGetLastErrorMsg();
    std::replace(message.begin(), message.end(), '\n', ' ');
    return message;
  }
};

struct GdalDatasetCloser {
  void operator()(GDALDataset* dataset) const { GDALClose(dataset); }
};
using DatasetPtr = std::unique_ptr<GDALDataset, GdalDatasetCloser>;

}  // namespace terratiles
