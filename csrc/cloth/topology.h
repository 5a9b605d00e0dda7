// Immutable flag topology: rest shape, springs, triangles, lumped masses and areas (paper §3).
#pragma once
#include <cstdint>
#include <vector>

#include "cloth/params.h"
#include "common/types.h"

namespace flagsim {

enum class SpringKind : int8_t { kStructural = 0, kShear = 1, kBend = 2 };

struct ClothTopology {
  int rows = 0, cols = 0;
  MatX3 rest_positions;  ///< (N x 3) m
  MatX2 uv;              ///< (N x 2) texture coordinates in [0,1]; u along +x, v up
  MatX3i triangles;      ///< (T x 3) counter-clockwise seen from +z at rest (normal +z)
  MatX2i springs;        ///< (S x 2) vertex pairs
  std::vector<SpringKind> spring_kind;  ///< (S)
  VecX rest_length;                     ///< (S) m
  VecX stiffness;                       ///< (S) N/m
  VecX damping;                         ///< (S) N s/m
  VecX area;      ///< (N) m^2, one third of each adjacent triangle's rest area (S in eq. 3)
  VecX mass;      ///< (N) kg, areal density x area
  VecX inv_mass;  ///< (N) 1/kg, 0 for pinned vertices
  // Vertex -> incident springs (CSR), so spring forces are gathered per vertex: parallel and
  // bit-identical for any thread count. adj_spring[k] for k in [adj_offset[i], adj_offset[i+1]).
  std::vector<int32_t> adj_offset;  ///< (N + 1)
  std::vector<int32_t> adj_spring;  ///< (2 S)
  std::vector<int32_t> adj_other;   ///< (2 S) the spring's other vertex
  // Vertex -> incident triangles (CSR): tri_adj[k] for k in [tri_adj_offset[i],
  // tri_adj_offset[i+1]).
  std::vector<int32_t> tri_adj_offset;  ///< (N + 1)
  std::vector<int32_t> tri_adj;         ///< (3 T)

  // Long-range attachment (Kim, Chentanez, Mueller 2012) of each vertex to its nearest pinned
  // vertex at rest: tether_anchor[i] (-1 for pinned vertices or when nothing is pinned) and the
  // rest distance tether_length[i], m. Used by strain limiting.
  std::vector<int32_t> tether_anchor;  ///< (N)
  VecX tether_length;                  ///< (N) m
  // Two more tethers per vertex, to the two pins farthest apart (the ends of a pole, a top edge,
  // both grommets): a tether to the nearest pin alone lets a vertex swing about it (sag 0.46 x
  // its distance on a pole) while staying within its length; the ends hold that swing to a few
  // degrees. tether_end_anchor[2 i + k], -1 where the end is the nearest pin or nothing is
  // pinned; tether_end_length[2 i + k], m, the rest distance (0 where the anchor is -1).
  std::vector<int32_t> tether_end_anchor;  ///< (2 N)
  VecX tether_end_length;                  ///< (2 N) m

  Index num_vertices() const { return rest_positions.rows(); }
  Index num_springs() const { return springs.rows(); }
  bool pinned(Index i) const { return inv_mass[i] == 0.0; }
};

/// Grid flag of params.rows x params.cols masses with structural, shear and bend springs.
ClothTopology build_flag_topology(const FlagParams& params);

/// The positions a Simulation starts from (N x 3, m): the rest positions, every unpinned mass
/// moved along the plane's normal (+z) by params.imperfection times a uniform number in [-1, 1]
/// from a counter-based hash of (imperfection_seed, vertex): the same bytes on every machine and
/// thread count. Equal to the rest positions when imperfection is 0.
MatX3 initial_positions(const ClothTopology& topo, const FlagParams& params);

/// Area-weighted vertex normals of the mesh at positions x (N x 3) into n (N x 3), unit length.
void compute_vertex_normals(const ClothTopology& topo, const MatX3& x, MatX3& n);

}  // namespace flagsim
