// mesh_write.cpp - the isosurface mesh as binary STL, OBJ and PLY files (vdb_io.h).
// Through Assimp's exporters (Debian libassimp-dev): a well-kept library rather than our own
// writers. The scene is built in memory (coordinates scaled to the file's unit), exported to
// a memory blob, the blob's header given the frame and unit, and the result written
// atomically (Assimp's own file output is not atomic). The only translation unit that
// includes Assimp.
#include "isotouch/io/vdb_io.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <memory>
#include <string_view>

#include "isotouch/io/output_file.h"
#include "isotouch/io/scan.h"

#ifdef ISOTOUCH_HAVE_ASSIMP
#include <assimp/Exporter.hpp>
#include <assimp/scene.h>
#endif

namespace isotouch::io {
namespace {
#ifdef ISOTOUCH_HAVE_ASSIMP

/// One mesh, one default material, one root node; the arrays sized for `nv` vertices and
/// `nt` triangles.
std::unique_ptr<aiScene> empty_scene(std::size_t nv, std::size_t nt) {
  auto scene = std::make_unique<aiScene>();
  scene->mRootNode = new aiNode();
  scene->mRootNode->mNumMeshes = 1;
  scene->mRootNode->mMeshes = new unsigned[1]{0};
  scene->mNumMaterials = 1;
  scene->mMaterials = new aiMaterial*[1]{new aiMaterial()};
  scene->mNumMeshes = 1;
  auto* am = new aiMesh();
  scene->mMeshes = new aiMesh*[1]{am};
  am->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  am->mMaterialIndex = 0;
  am->mNumVertices = unsigned(nv);
  am->mVertices = new aiVector3D[nv];
  am->mNormals = new aiVector3D[nv];
  am->mNumFaces = unsigned(nt);
  am->mFaces = new aiFace[nt];
  return scene;
}

/// (b - a) x (c - a): the triangle's right-hand normal, twice its area long.
std::array<double, 3> area_normal(const Mesh& m, const std::array<std::uint32_t, 3>& t) {
  const auto &a = m.vertices[t[0]], &b = m.vertices[t[1]], &c = m.vertices[t[2]];
  const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  return {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
}

aiVector3D scaled(const std::array<double, 3>& p, double k) {
  return aiVector3D(float(p[0] * k), float(p[1] * k), float(p[2] * k));
}

/// 3 vertices per triangle with the triangle's exact unit normal (STL's facets).
std::unique_ptr<aiScene> triangle_soup(const Mesh& m, double k) {
  auto scene = empty_scene(3 * m.triangles.size(), m.triangles.size());
  aiMesh* am = scene->mMeshes[0];
  for (std::size_t f = 0; f < m.triangles.size(); ++f) {
    const auto& t = m.triangles[f];
    const auto n = area_normal(m, t);
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    const aiVector3D normal = len > 0 ? scaled(n, 1 / len) : aiVector3D(0, 0, 0);
    aiFace& face = am->mFaces[f];
    face.mNumIndices = 3;
    face.mIndices = new unsigned[3];
    for (unsigned c = 0; c < 3; ++c) {
      am->mVertices[3 * f + c] = scaled(m.vertices[t[c]], k);
      am->mNormals[3 * f + c] = normal;
      face.mIndices[c] = unsigned(3 * f + c);
    }
  }
  return scene;
}

/// Shared vertices with area-weighted unit vertex normals (OBJ, PLY).
std::unique_ptr<aiScene> shared_vertices(const Mesh& m, double k) {
  auto scene = empty_scene(m.vertices.size(), m.triangles.size());
  aiMesh* am = scene->mMeshes[0];
  for (std::size_t i = 0; i < m.vertices.size(); ++i) {
    am->mVertices[i] = scaled(m.vertices[i], k);
    am->mNormals[i] = aiVector3D(0, 0, 0);
  }
  for (std::size_t f = 0; f < m.triangles.size(); ++f) {
    const auto& t = m.triangles[f];
    const aiVector3D n = scaled(area_normal(m, t), 1);
    aiFace& face = am->mFaces[f];
    face.mNumIndices = 3;
    face.mIndices = new unsigned[3];
    for (unsigned c = 0; c < 3; ++c) {
      face.mIndices[c] = t[c];
      am->mNormals[t[c]] += n;
    }
  }
  for (std::size_t i = 0; i < m.vertices.size(); ++i) am->mNormals[i].NormalizeSafe();
  return scene;
}

/// Assimp's blob of `format` as bytes. @throws VdbError naming the path.
std::string export_blob(const aiScene& scene, const std::string& path, const char* format) {
  Assimp::Exporter exporter;
  const aiExportDataBlob* blob = exporter.ExportToBlob(&scene, format, 0u);
  if (!blob) throw VdbError(path + ": Assimp's '" + format + "' exporter failed: " + exporter.GetErrorString());
  return std::string(static_cast<const char*>(blob->data), blob->size);
}
#endif

/// Binary STL's 80-byte header (Assimp's) replaced by `text`, zero-padded. It never starts
/// with "solid", which would make readers take the file for ASCII STL.
void stamp_stl(std::string& bytes, const std::string& text, const std::string& path) {
  if (bytes.size() < 84) throw VdbError(path + ": the STL exporter wrote " + std::to_string(bytes.size()) + " bytes, less than a header");
  std::memset(bytes.data(), 0, 80);
  std::memcpy(bytes.data(), text.data(), std::min<std::size_t>(text.size(), 80));
}

/// `text` as the OBJ's first line, a comment (3D Slicer reads the comment at the top).
void stamp_obj(std::string& bytes, const std::string& text) { bytes.insert(0, "# " + text + "\n"); }

/// `text` as a "comment" line right after PLY's "format" line (comments go in the header).
void stamp_ply(std::string& bytes, const std::string& text, const std::string& path) {
  const std::size_t format = bytes.find("\nformat ");
  const std::size_t end = format == std::string::npos ? format : bytes.find('\n', format + 1);
  if (bytes.rfind("ply\n", 0) != 0 || end == std::string::npos)
    throw VdbError(path + ": the PLY exporter's header does not start with 'ply' and 'format': not written");
  bytes.insert(end + 1, "comment " + text + "\n");
}

enum class Format { kStl, kObj, kPly };

void export_mesh(const Mesh& m, const std::string& path, Format format, MeshUnits units) {
  if (m.triangles.empty()) throw VdbError(path + ": the mesh is empty (no surface at this isovalue?), nothing written");
#ifdef ISOTOUCH_HAVE_ASSIMP
  const double k = units_per_metre(units);
  const std::string text = mesh_header_text(units);
  std::string bytes;
  if (format == Format::kStl) {
    bytes = export_blob(*triangle_soup(m, k), path, "stlb");
    stamp_stl(bytes, text, path);
  } else {
    bytes = export_blob(*shared_vertices(m, k), path, format == Format::kObj ? "objnomtl" : "plyb");
    if (format == Format::kObj) stamp_obj(bytes, text);
    else stamp_ply(bytes, text, path);
  }
  try {
    write_output(path, std::string_view(bytes));
  } catch (const OutputError& e) {
    throw VdbError(e.what());
  }
#else
  (void)format;
  (void)units;
  throw VdbError(path + ": built without Assimp (Debian: libassimp-dev), mesh files unavailable");
#endif
}

}  // namespace

std::string mesh_header_text(MeshUnits units) {
  return std::string("isotouch mesh SPACE=LPS UNITS=") + to_string(units);
}

void write_stl_binary(const Mesh& mesh, const std::string& path, MeshUnits units) {
  export_mesh(mesh, path, Format::kStl, units);
}
void write_obj(const Mesh& mesh, const std::string& path, MeshUnits units) {
  export_mesh(mesh, path, Format::kObj, units);
}
void write_ply(const Mesh& mesh, const std::string& path, MeshUnits units) {
  export_mesh(mesh, path, Format::kPly, units);
}

std::string mesh_format(const std::string& path) {
  const std::string ext = lower_extension(path);
  return ext == ".stl" || ext == ".obj" || ext == ".ply" ? ext.substr(1) : "";
}

void write_mesh(const Mesh& mesh, const std::string& path, MeshUnits units) {
  const std::string f = mesh_format(path);
  if (f == "stl") write_stl_binary(mesh, path, units);
  else if (f == "obj") write_obj(mesh, path, units);
  else if (f == "ply") write_ply(mesh, path, units);
  else throw VdbError(path + ": unknown mesh format: the name must end in .stl (binary STL), .obj or .ply");
}

}  // namespace isotouch::io
