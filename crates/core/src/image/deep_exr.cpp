// Writes a deep scanline OpenEXR file through OpenEXR's own library (ImfDeepScanLineOutputFile),
// for src/image/deep_exr.rs. One part, channels R G B A Z ZBack as 32-bit float, ZIPS
// compression (what deep renderers write and Nuke's DeepRead reads), and the header entries
// the flat file carries. Every OpenEXR exception is caught and returned as text: nothing is
// thrown across the C boundary.

#include <cstdint>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include <ImfChannelList.h>
#include <ImfChromaticities.h>
#include <ImfDeepFrameBuffer.h>
#include <ImfDeepScanLineOutputFile.h>
#include <ImfHeader.h>
#include <ImfRational.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>

extern "C" {

// What the header holds besides the pixels (see ExrHeader in exr_header.rs).
struct NerfxDeepHeader {
    float pixel_aspect;
    // red, green, blue, white: x then y.
    float chromaticities[8];
    int has_world_to_camera;
    float world_to_camera[16];
    int has_world_to_ndc;
    float world_to_ndc[16];
    int has_fps;
    int fps_numerator;
    unsigned fps_denominator;
    // deepImageState: 1 tidy (sorted and non-overlapping samples), 0 not written.
    int tidy;
    size_t entries;
    const char *const *keys;
    const char *const *values;
};

// Writes `width`×`height` pixels; pixel p (row-major from the top-left) holds `counts[p]`
// samples, stored from `offsets[p]` in each of the six arrays of `channels` (R G B A Z ZBack).
// Returns 0, or 1 with a message in `error` (NUL-terminated, cut to `error_len`).
int nerfx_write_deep_scanline(const char *path, int width, int height, const uint32_t *counts,
                              const uint64_t *offsets, const float *const *channels,
                              const NerfxDeepHeader *header, char *error, size_t error_len) {
    try {
        using namespace Imf;
        Header h(width, height, header->pixel_aspect);
        h.compression() = ZIPS_COMPRESSION;
        const char *names[6] = {"R", "G", "B", "A", "Z", "ZBack"};
        for (const char *name : names) {
            h.channels().insert(name, Channel(FLOAT));
        }
        const float *c = header->chromaticities;
        addChromaticities(h, Chromaticities(IMATH_NAMESPACE::V2f(c[0], c[1]),
                                            IMATH_NAMESPACE::V2f(c[2], c[3]),
                                            IMATH_NAMESPACE::V2f(c[4], c[5]),
                                            IMATH_NAMESPACE::V2f(c[6], c[7])));
        auto matrix = [](const float *m) {
            return IMATH_NAMESPACE::M44f(m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8],
                                         m[9], m[10], m[11], m[12], m[13], m[14], m[15]);
        };
        if (header->has_world_to_camera) {
            addWorldToCamera(h, matrix(header->world_to_camera));
        }
        if (header->has_world_to_ndc) {
            addWorldToNDC(h, matrix(header->world_to_ndc));
        }
        if (header->has_fps) {
            addFramesPerSecond(h, Rational(header->fps_numerator, header->fps_denominator));
        }
        if (header->tidy) {
            addDeepImageState(h, DIS_TIDY);
        }
        h.insert("software", StringAttribute("nerfx"));
        for (size_t i = 0; i < header->entries; ++i) {
            h.insert(header->keys[i], StringAttribute(header->values[i]));
        }

        const size_t pixels = size_t(width) * size_t(height);
        // Per channel, a pointer to each pixel's first sample (a pixel without samples
        // still gets a valid pointer: OpenEXR reads none through it).
        std::vector<std::vector<const float *>> starts(6, std::vector<const float *>(pixels));
        for (int k = 0; k < 6; ++k) {
            for (size_t p = 0; p < pixels; ++p) {
                starts[k][p] = channels[k] + offsets[p];
            }
        }
        DeepFrameBuffer buffer;
        buffer.insertSampleCountSlice(Slice(UINT, (char *)counts, sizeof(uint32_t),
                                            sizeof(uint32_t) * size_t(width)));
        for (int k = 0; k < 6; ++k) {
            buffer.insert(names[k], DeepSlice(FLOAT, (char *)starts[k].data(), sizeof(float *),
                                              sizeof(float *) * size_t(width), sizeof(float)));
        }
        DeepScanLineOutputFile file(path, h);
        file.setFrameBuffer(buffer);
        file.writePixels(height);
        return 0;
    } catch (const std::exception &e) {
        if (error_len > 0) {
            std::strncpy(error, e.what(), error_len - 1);
            error[error_len - 1] = '\0';
        }
        return 1;
    } catch (...) {
        if (error_len > 0) {
            std::strncpy(error, "unknown OpenEXR error", error_len - 1);
            error[error_len - 1] = '\0';
        }
        return 1;
    }
}
}
