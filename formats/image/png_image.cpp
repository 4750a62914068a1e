#include "formats/image/png_image.h"

#include <gdal_priv.h>

#include <atomic>
#include <memory>

#include "formats/gdal_support.h"
#include "src/base/error.h"

namespace terratiles {

std::vector<std::uint8_t> encodePng(const RgbImage& image) {
  TERRATILES_ASSERT(image.width > 0 && image.height > 0 &&
                    image.rgb.size() == static_cast<std::size_t>(image.width) * image.height * 3);
  GDALAllRegister();
  GDALDriver* mem = GetGDALDriverManager()->GetDriverByName("MEM");
  GDALDriver* png = GetGDALDriverManager()->GetDriverByName("PNG");
  if (!mem || !png) throw Error(ErrorCode::Internal, "GDAL has no MEM or PNG driver; cannot draw report maps");
  DatasetPtr source(mem->Create("", image.width, image.height, 3, GDT_Byte, nullptr));
  if (!source) throw Error(ErrorCode::Internal, "GDAL could not create an in-memory image");
  for (int band = 0; band < 3; ++band) {
    // Pixel-interleaved source: 3 bytes between pixels, 3 * width between lines.
    const CPLErr status = source->GetRasterBand(band + 1)->RasterIO(
        GF_Write, 0, 0, image.width, image.height, const_cast<std::uint8_t*>(image.rgb.data()) + band,
        image.width, image.height, GDT_Byte, 3, 3 * image.width);
    if (status != CE_None) throw Error(ErrorCode::Internal, "GDAL could not fill an in-memory image");
  }
  static std::atomic<unsigned> counter{0};
  const std::string path = "/vsimem/terratiles_report_" + std::to_string(counter++) + ".png";
  {
    DatasetPtr written(png->CreateCopy(path.c_str(), source.get(), FALSE, nullptr, nullptr, nullptr));
    if (!written) throw Error(ErrorCode::Internal, "GDAL could not encode a PNG image");
  }
  vsi_l_offset length = 0;
  GByte* data = VSIGetMemFileBuffer(path.c_str(), &length, TRUE);  // takes ownership
  if (!data) throw Error(ErrorCode::Internal, "GDAL wrote no PNG bytes");
  std::vector<std::uint8_t> bytes(data, data + length);
  CPLFree(data);
  VSIUnlink((path + ".aux.xml").c_str());
  return bytes;
}

std::string dataUri(const std::vector<std::uint8_t>& bytes, const std::string& mime) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out = "data:" + mime + ";base64,";
  out.reserve(out.size() + (bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const std::uint32_t v = (bytes[i] << 16) | (bytes[i + 1] << 8) | bytes[i + 2];
    out += {kAlphabet[v >> 18], kAlphabet[(v >> 12) & 63], kAlphabet[(v >> 6) & 63], kAlphabet[v & 63]};
  }
  if (i + 1 == bytes.size()) {
    const std::uint32_t v = bytes[i] << 16;
    out += {kAlphabet[v >> 18], kAlphabet[(v >> 12) & 63], '=', '='};
  } else if (i + 2 == bytes.size()) {
    const std::uint32_t v = (bytes[i] << 16) | (bytes[i + 1] << 8);
    out += {kAlphabet[v >> 18], kAlphabet[(v >> 12) & 63], kAlphabet[(v >> 6) & 63], '='};
  }
  return out;
}

}  // namespace terratiles
