// vdb_io.h - OpenVDB in and out, and the isosurface as a mesh.
//
// A plain C++ API: every OpenVDB include stays in vdb_io.cpp (slow to compile), every mesh
// library include too (Assimp, Debian libassimp-dev).
//
// Frames. The .vdb transform holds the *grid-world* frame [m] (core/grid.h): index (i, j, k)
// -> origin + spacing * (i, j, k), a scale + translation, which every OpenVDB tool reads;
// the volume's direction matrix D (engine::Volume) travels in the grid's metadata. Meshes
// are made in the *physical* frame [m] (origin + D (world - origin)), ITK's LPS, the frame
// every point shown to a user is in, and written in it in millimetres (io/mesh_units.h); with
// D = identity (all synthetic volumes, MetaImage/NRRD in LPS without rotation) the two coincide.
#pragma once
#include <array>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/core/isosurface.h"
#include "isotouch/engine/volume.h"
#include "isotouch/io/mesh_units.h"
#include "isotouch/io/volume_io.h"

namespace isotouch::io {

/// A .vdb or mesh file problem. what() names the file, the grid or field, and the problem.
struct VdbError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Margin [voxels] added around a foreign grid's active bounding box when it is made dense.
inline constexpr int kVdbLoadMarginVox = 1;

/// What load_vdb returns: the dense volume and what the file says about its isosurface.
struct LoadedVdb {
  engine::Volume volume;  ///< dense over the box (see load_vdb), path = the .vdb file
  /// The isosurface the file suggests: tau 0, inside "below" for a level set
  /// (GRID_LEVEL_SET); the saved isovalue and inside for a file written by save_vdb;
  /// none otherwise.
  std::optional<core::Isosurface> suggested;
  std::string grid_name;    ///< the grid that was read
  std::string grid_class;   ///< "level set", "fog volume", "staggered", "unknown"
  float background = 0;     ///< the grid's background value (fills voxels outside its data)
  std::string source_path;  ///< "isotouch_source" metadata of save_vdb ("" if absent)
  bool written_by_isotouch = false;  ///< the grid carries save_vdb's box metadata
};

/// Load a FloatGrid from a .vdb file into a dense engine::Volume.
///
/// Grid: the named one (must be a FloatGrid), or the first FloatGrid of the file.
/// Transform: must be linear with an axis-aligned positive scale (uniform or not) and a
/// translation; world units are taken as metres. Anything else (rotation, shear, negative
/// scale, frustum) is refused naming the file, the grid and the transform's matrix.
/// Box: for a file written by save_vdb, exactly the saved volume's voxels (the box is in
/// its metadata), so save + load gives the identical Volume back. Otherwise the active
/// voxels' bounding box (active tiles included) grown by kVdbLoadMarginVox and widened so
/// that the box starts and ends on multiples of 8 in index space: its 8^3 bricks
/// (core/brick_field.h) are the grid's leaf nodes. Every voxel of the box reads the grid's
/// value there (inactive voxels and tiles included: a level set's inside reads
/// -background), outside the grid's data the background.
/// Voxel (0,0,0) of the volume sits at index `box min` of the grid: origin_m = its world.
/// @param max_voxels the largest box accepted (voxels), 2^31 by default.
/// @throws VdbError "FILE: ..." for a missing file, a file that is not a .vdb, no FloatGrid
///         (the grids found are listed), a named grid that is absent or not float, an empty
///         grid (no active voxel), a box above max_voxels, a refused transform.
LoadedVdb load_vdb(const std::string& path, const std::string& grid_name = "",
                   std::uint64_t max_voxels = io::kMaxVoxels);

/// Any volume file isotouch reads: a .vdb (its first FloatGrid, through load_vdb) or what
/// io::load_volume reads (MetaImage, NRRD, NIfTI). run, render, check and export all
/// load through this, so whatever export writes goes wherever a volume does.
/// @throws VdbError or engine::VolumeError naming the file.
engine::Volume load_any_volume(const std::string& path);

struct SaveVdbOptions {
  std::string grid_name = "volume";          ///< name of the FloatGrid written
  std::optional<core::Isosurface> iso;       ///< saved as metadata (and sets the background)
  std::string source_path;                   ///< saved as "isotouch_source" (default: volume.path)
};

/// Write a volume as a .vdb FloatGrid, atomically.
///
/// Contents: every voxel of the volume is an *active* voxel holding its exact float (NaN,
/// -0.0 and all: no tolerance, no pruning, no half floats), so load_vdb gives every voxel
/// back bit for bit. Voxel (i, j, k) is index coordinate (i, j, k); the transform is the
/// grid-world frame (scale = spacing_m, translation = origin_m). Background (the value
/// OpenVDB tools read outside the volume): `iso->outside_value(min, max)` when an
/// isosurface is given (outside reads as outside the object, and a mesh closes at the
/// border), else the smallest finite voxel (0 if there is none).
/// Metadata: isotouch_isovalue (double) and isotouch_inside ("above"/"below") when iso is
/// given; isotouch_source; isotouch_box_min / isotouch_dims (the voxel box); isotouch_direction
/// (D, row-major, as a 4x4 matrix); isotouch_spacing_m / isotouch_origin_m (exact: OpenVDB's
/// transform re-derives the scale with an ULP of rounding); isotouch_units = "m"; reader and
/// component type.
/// Atomic: written to a temp file PATH.tmp-PID-XXXXXX in the same folder, flushed and
/// fsync'ed, renamed over PATH, then the folder fsync'ed: a crash at any moment leaves
/// either the old PATH whole or the new one whole (and possibly a stray temp file, never
/// named like PATH).
/// @throws VdbError naming the path and the OS error (folder missing, no permission, disk full).
void save_vdb(const engine::Volume& volume, const std::string& path, const SaveVdbOptions& options = {});

/// True for the names save_any_volume writes (any case): .vdb, and what
/// io::save_volume_itk writes (.mha, .nrrd, .nii, .nii.gz).
bool volume_writable(const std::string& path);

/// Writes `volume` in the format its name asks for: .vdb through save_vdb (with `options`),
/// .mha / .nrrd / .nii / .nii.gz through io::save_volume_itk (3D Slicer opens them). Any
/// other name is refused before anything is written.
/// @throws VdbError naming the path (and the names taken) or the write's error.
void save_any_volume(const engine::Volume& volume, const std::string& path, const SaveVdbOptions& options = {});

/// A triangle mesh, vertices in the physical frame [m], triangles counter-clockwise seen
/// from outside the object (right-hand normals point out of the object).
struct Mesh {
  std::vector<std::array<double, 3>> vertices;        ///< physical [m]
  std::vector<std::array<std::uint32_t, 3>> triangles;  ///< indices into vertices
  std::size_t welded_vertices = 0;     ///< extract_mesh: vertices merged into one at the same position
  std::size_t dropped_triangles = 0;   ///< extract_mesh: zero-area triangles dropped after welding
};

/// The isosurface of a volume as a closed triangle mesh, by openvdb::tools::volumeToMesh
/// (quads split into two triangles along their 0-2 diagonal). The volume is copied into a
/// FloatGrid whose outside (beyond the grid) reads as outside the object, so the mesh is
/// closed also where the object touches the border: there the surface is half a voxel
/// beyond the border voxels' centres (a 1-voxel shell mirrors them about tau). volumeToMesh
/// can put two vertices at one position (a corner value exactly at tau): those are welded
/// and the triangles that become degenerate are dropped, so no triangle has zero area and
/// the mesh stays closed (each edge in exactly two triangles). NaN voxels
/// count as outside (as in core::Isosurface). tau is compared as a float (OpenVDB's
/// isovalue type). Vertices are mapped index -> grid-world -> physical [m]; the winding
/// is flipped where D has determinant -1 so normals still point out.
/// @param adaptivity in [0, 1]: 0 = uniform (one vertex per crossed cell), larger merges
///        flat regions into fewer, larger polygons.
/// @throws VdbError for an empty volume or an adaptivity outside [0, 1].
Mesh extract_mesh(const engine::Volume& volume, const core::Isosurface& iso, double adaptivity = 0);

/// Figures of a mesh (from the triangles, in the mesh's units).
struct MeshStats {
  std::size_t triangles = 0, vertices = 0;
  double area_m2 = 0;           ///< sum of triangle areas
  double signed_volume_m3 = 0;  ///< divergence theorem; > 0 when normals point out
  std::size_t edges = 0;              ///< distinct undirected edges
  std::size_t boundary_edges = 0;     ///< edges in exactly 1 triangle
  std::size_t nonmanifold_edges = 0;  ///< edges in 3 or more triangles
  std::size_t degenerate_triangles = 0;  ///< triangles with a repeated vertex index
  std::array<double, 3> min{0, 0, 0}, max{0, 0, 0};  ///< bounding box
  bool closed() const { return triangles > 0 && boundary_edges == 0 && nonmanifold_edges == 0; }
};
MeshStats mesh_stats(const Mesh& mesh);

/// Mesh writers, each atomic (temp file in the same folder + fsync + rename), through
/// Assimp's exporters ("stlb", "objnomtl", "plyb"). Coordinates as float32 in the physical
/// frame (LPS) in `units`: millimetres by default, as 3D Slicer and 3D-printing slicers read
/// them; metres on request. The file says both where its format has room for text, in the
/// words 3D Slicer looks for ("SPACE=LPS"): binary STL's 80-byte header, the first line of
/// the OBJ ("# ..."), a PLY "comment" line.
/// Binary STL (little-endian, 3D printing: one facet normal per triangle, the exact
/// right-hand normal of its vertices); OBJ (text, no material file: v, vn, f); PLY
/// (binary little-endian: vertex x y z nx ny nz float, face vertex_indices).
/// @throws VdbError naming the path and the problem.
void write_stl_binary(const Mesh& mesh, const std::string& path, MeshUnits units = MeshUnits::kMillimetre);
void write_obj(const Mesh& mesh, const std::string& path, MeshUnits units = MeshUnits::kMillimetre);
void write_ply(const Mesh& mesh, const std::string& path, MeshUnits units = MeshUnits::kMillimetre);

/// The text a mesh file carries about its frame and unit, e.g.
/// "isotouch mesh SPACE=LPS UNITS=mm" (what the writers above put in the header).
std::string mesh_header_text(MeshUnits units);

/// The mesh format a name asks for: "stl", "obj" or "ply" (its extension, any case), else "".
std::string mesh_format(const std::string& path);

/// Writes `mesh` in the format its name asks for (mesh_format): binary STL, OBJ or PLY.
/// @throws VdbError naming the path and the names taken for any other name, before writing.
void write_mesh(const Mesh& mesh, const std::string& path, MeshUnits units = MeshUnits::kMillimetre);

/// Test helpers: .vdb files made with OpenVDB itself, so tests need not include OpenVDB.
enum class TestVdb {
  kLevelSetSphere,  ///< tools::createLevelSetSphere: radius 20 voxels, voxel 1 mm, centre (0,0,0), half-width 3
  kNoFloatGrid,     ///< one Int32Grid and one Vec3SGrid, no FloatGrid
  kEmptyFloatGrid,  ///< a FloatGrid with no active voxel
  kHugeBox,         ///< a FloatGrid with two active voxels 100000 voxels apart on each axis
  kWrappingBox,     ///< two active voxels whose box is 2^31 x 2^17 x 2^16 (int32 extents wrap)
  kRotated,         ///< a FloatGrid with a 30-degree rotation about z in its transform
  /// A FloatGrid whose active tiles fill 1920 x 1024 x 1024 voxels of 1 mm, in a file of a few
  /// kB: loaded with its margin, 1936 x 1040 x 1040 (just below the voxel limit; 8 GB dense).
  kTileBox,
};
/// Write one of the TestVdb files (not atomic; tests only).
void write_test_vdb(const std::string& path, TestVdb kind);

}  // namespace isotouch::io
