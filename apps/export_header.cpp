#include "export_header.hpp"

#include <cstdio>
#include <filesystem>

#include "cli.hpp"
#include "tsah/base/error.hpp"

#include "tsah/layout/wide_layout.hpp"

namespace tsah::cli {

std::string binaryExportTypes() {
  return R"(typedef struct TsahBvhNode {
  float c0loX, c0hiX, c0loY, c0hiY; /* child 0 box, x and y */
  float c1loX, c1hiX, c1loY, c1hiY; /* child 1 box, x and y */
  float c0loZ, c0hiZ, c1loZ, c1hiZ; /* both boxes, z */
  int32_t ref0, ref1;               /* child references */
  uint32_t count0, count1;          /* leaf triangle counts, 0 for interior children */
} TsahBvhNode;                      /* 64 bytes; align to 16 for vector loads */

typedef struct TsahFloat4 { float x, y, z, w; } TsahFloat4;
typedef struct TsahWoopTriangle { TsahFloat4 r0, r1, r2; } TsahWoopTriangle; /* 48 bytes */

#if defined(__STDC_VERSION__) && __STDC_VERSION__ >= 201112L
_Static_assert(sizeof(TsahBvhNode) == 64, "TsahBvhNode must be 64 bytes");
_Static_assert(sizeof(TsahWoopTriangle) == 48, "TsahWoopTriangle must be 48 bytes");
#elif defined(__cplusplus)
static_assert(sizeof(TsahBvhNode) == 64, "TsahBvhNode must be 64 bytes");
static_assert(sizeof(TsahWoopTriangle) == 48, "TsahWoopTriangle must be 48 bytes");
#endif

)";
}

namespace {

template <uint32_t N>
std::string wideTypes() {
  const std::string n = std::to_string(N);
  std::string h;
  h += "#define TSAH_WIDTH " + n + "u\n";
  h += "typedef struct TsahBvh" + n + "Node {\n  float box[6][" + n + "];   /* lo.x, lo.y, lo.z, hi.x, hi.y, hi.z of each child */\n";
  h += "  int32_t ref[" + n + "];     /* child references */\n  uint32_t count[" + n +
       "];  /* leaf triangle counts, 0 for interior children and unused slots */\n";
  h += "} TsahBvh" + n + "Node;      /* " + std::to_string(sizeof(tsah::WideSoaNode<N>)) + " bytes; align to " +
       std::to_string(alignof(tsah::WideSoaNode<N>)) + " */\n\n";
  h += "typedef struct TsahWoopPacket" + n + " {\n  float row[12][" + n + "];  /* r0.x r0.y r0.z r0.w r1.x ... r2.w per lane */\n";
  h += "  uint32_t slot[" + n + "];   /* triangle slot of each lane */\n";
  h += "} TsahWoopPacket" + n + ";    /* " + std::to_string(sizeof(tsah::WoopPacket<N>)) + " bytes */\n\n";
  const std::string nodeSize = std::to_string(sizeof(tsah::WideSoaNode<N>));
  const std::string packetSize = std::to_string(sizeof(tsah::WoopPacket<N>));
  for (const char* how : {"#if defined(__STDC_VERSION__) && __STDC_VERSION__ >= 201112L\n_Static_assert",
                          "#elif defined(__cplusplus)\nstatic_assert"}) {
    h += std::string(how) + "(sizeof(TsahBvh" + n + "Node) == " + nodeSize + ", \"node size\");\n";
    h += std::string(how).substr(std::string(how).find('\n') + 1) + "(sizeof(TsahWoopPacket" + n + ") == " + packetSize +
         ", \"packet size\");\n";
  }
  h += "#endif\n\n";
  return h;
}

}  // namespace

std::string wideExportTypes(uint32_t width) { return width == 8 ? wideTypes<8>() : wideTypes<4>(); }

std::string woopTestComment() {
  return R"( * Woop test (rows r0, r1, r2 of a WoopTriangle; o = ray origin, d = direction):
 *   t  = (r0.w - dot(o, r0.xyz)) / dot(d, r0.xyz)
 *   b0 = r1.w + dot(o, r1.xyz) + t * dot(d, r1.xyz)   (weight of vertex 0)
 *   b1 = r2.w + dot(o, r2.xyz) + t * dot(d, r2.xyz)   (weight of vertex 1)
 *   hit when tmin < t < tmax, b0 >= 0, b1 >= 0, b0 + b1 <= 1. Degenerate triangles have zero rows.
 *   For watertight results near edges, test the vertices (Woop, Benthin, Wald 2013) there instead.
)";
}

std::string cFloatLiteral(float v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.9gf", double(v));
  return buf;
}

void makeExportFolder(const std::string& out) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::exists(out, ec) && !fs::is_directory(out, ec)) throw UsageError(out + " exists and is not a folder");
  fs::create_directories(out, ec);
  if (ec) throw Failure(out + ": cannot create the folder: " + ec.message());
}

}  // namespace tsah::cli
