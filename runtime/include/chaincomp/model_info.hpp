// Machine-independent description of a generated model: names, units and limits of its
// axes and parameters, and type-erased entry points, so the runtime can pick a compiled
// model by machine name and fill its parameters by name.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace chaincomp {

struct VaryingErrors;  // varying.hpp

enum class UnitKind : int { kLength = 0, kAngle = 1, kRatio = 2 };
enum class ParamRole : int { kConstant = 0, kError = 1 };

struct AxisInfo {
  const char* name;
  const char* unit;      // declared unit (mm, deg, ...): the unit on the wire
  UnitKind kind;
  double to_internal;    // declared unit -> mm or rad
  double lower, upper;   // limits in the declared unit
};

struct ParamInfo {
  const char* name;
  ParamRole role;
  const char* unit;      // declared unit
  UnitKind kind;
  double to_internal;    // declared unit -> mm, rad or 1
  double nominal;        // internal units (errors: 0)
};

struct MachineInfo {
  const char* name;
  std::uint64_t source_hash;  // FNV-1a 64 of the machine file the model was generated from
  const char* source_file;
  int num_axes;
  const AxisInfo* axes;
  int num_params;
  const ParamInfo* params;
  int pose_size;              // 3 (tool point), 6 (point, tool direction) or 9 (point, direction,
                              // the tool frame's x axis: a six-DOF frame)
  bool corrects_direction;    // compensation also corrects the tool direction
  bool corrects_orientation;  // ... and, with a frame and three or more rotary axes, the full
                              // orientation (compensate.hpp's kCorrectsOrientation)
};

// Type-erased entry points of one generated model; buffers are in internal units.
struct ModelEntry {
  const MachineInfo* info;
  std::size_t model_size;   // bytes of the model object prepare() fills
  std::size_t model_align;
  void (*prepare)(const double* params, void* model) noexcept;
  void (*pose_exact)(const void* model, const double* axes, double* pose) noexcept;
  void (*pose_nominal)(const void* model, const double* axes, double* pose) noexcept;
  // pose and its Jacobian (pose_size x num_axes, column-major) with respect to the axes.
  void (*pose_jacobian)(const void* model, const double* axes, double* pose, double* jacobian) noexcept;
  // Tool error of the order-k truncated model, k = 1 .. max_order; false for another k.
  bool (*error)(const void* model, const double* axes, int order, double* pose) noexcept;
  int max_order;
  // Returns a chaincomp::Status code; residual[0] point (mm), residual[1] direction (rad),
  // with a frame corrected in full the orientation residual (rad; compensate.hpp); `before`
  // (may be null) the same two of the command itself. `direction_weight`: the objective's, mm
  // per rad (compensate.hpp; the runtime config's direction_weight).
  // `workspace`: null (every call starts cold), or one set up by init_workspace and kept
  // across the commands of a stream (each starts from the last correction: compensate.hpp).
  int (*compensate)(const void* model, void* workspace, const double* command, double direction_weight,
                    double* corrected, double* residual, double* before) noexcept;
  std::size_t workspace_size;  // bytes of the workspace object init_workspace constructs
  std::size_t workspace_align;
  void (*init_workspace)(void* workspace) noexcept;
  int num_errors;  // error parameters (kParams order): the columns of the error gain matrix
  // Errors that vary along an axis (params_io.hpp's load_params), attached after prepare()
  // (which detaches them); they must outlive the model. Every entry point above then
  // evaluates them at its axes; outside a range that rejects, poses are NaN and compensate
  // returns kOutsideTable.
  void (*attach_varying)(void* model, const VaryingErrors* varying) noexcept;
  // pose_jacobian (with the varying errors' slopes), and the error gain matrix d pose / d error
  // at zero errors (pose_size x num_errors, column-major; `gain` may be null).
  void (*pose_jacobian_gain)(const void* model, const double* axes, double* pose, double* jacobian,
                             double* gain) noexcept;
  // pose_exact with each varying error held at the end of a range that rejects, as
  // compensate's iterates see it: the pose at a corrected target a little past the end.
  void (*pose_exact_held)(const void* model, const double* axes, double* pose) noexcept;
};

// Sizes `storage` for an object of `size` bytes aligned to `align` (a model, a workspace)
// and returns where it goes. Start-up only: it allocates.
inline void* aligned_slot(std::vector<unsigned char>& storage, std::size_t size, std::size_t align) {
  storage.assign(size + align, 0);
  void* p = storage.data();
  std::size_t space = storage.size();
  return std::align(align, size, p, space);
}

struct UnitInfo {
  const char* name;
  UnitKind kind;
  double to_internal;
};
// The units a machine or params file may use (the same table as the Python package's).
const UnitInfo* find_unit(const char* name) noexcept;

// The registry of every model compiled into chaincomp_models (generated registry.cpp).
const ModelEntry* find_model(const char* name) noexcept;
std::size_t model_count() noexcept;
const ModelEntry* model_at(std::size_t i) noexcept;

}  // namespace chaincomp
