#pragma once
// encodePng: an RGB image as PNG bytes (GDAL's PNG driver through /vsimem/, no file), and
// dataUri: bytes as a data: URI, for self-contained HTML reports.

#include <cstdint>
#include <string>
#include <vector>

namespace terratiles {

struct RgbImage {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgb;  // row-major, top row first, 3 bytes per pixel

  RgbImage() = default;
  RgbImage(int w, int h, std::uint8_t grey) : width(w), height(h), rgb(static_cast<std::size_t>(w) * h * 3, grey) {}
  std::uint8_t* at(int x, int y) { return &rgb[(static_cast<std::size_t>(y) * width + x) * 3]; }
};

// Throws Error(Internal) when GDAL cannot encode it.
std::vector<std::uint8_t> encodePng(const RgbImage& image);

// "data:<mime>;base64,..." (RFC 2397, RFC 4648 base64).
std::string dataUri(const std::vector<std::uint8_t>& bytes, const std::string& mime);

}  // namespace terratiles
