/* The C interface between chaincomp_rt's HAL glue (chaincomp_rt.c) and its C++ core
 * (chaincomp_rt_core.cpp). */
#ifndef CHAINCOMP_RT_H
#define CHAINCOMP_RT_H

#ifdef __cplusplus
extern "C" {
#endif

struct ccrt_result {
  int reject;      /* -1: a target; else the chaincomp::Reject reason the command was refused for */
  int flags;       /* lcmt_corrected_target.FLAG_* of the target */
  int status;      /* chaincomp::Status of the target */
  double ramp;     /* 0 (off) .. 1 (fully on) */
  double residual_point;      /* mm */
  double residual_direction;  /* rad */
};

/* Module load (allocates): prepares the model with its params, builds the compensator.
 * 0, or -1 with a message in error. */
int ccrt_init(char* error, int size);
void ccrt_fini(void);
int ccrt_num_axes(void);
const char* ccrt_machine(void);
const char* ccrt_params_file(void);
const char* ccrt_axis_name(int i);
/* One servo period, allocation-free: joint commands in LinuxCNC units (mm, deg); on 1 the
 * corrections (LinuxCNC units) are in correction[]; on 0 the command was refused. */
int ccrt_step(const double* joint_cmd, int enable, long long utime_us, double* correction,
              struct ccrt_result* result);
/* The errors a HAL pin may set while running (the machine's constant errors), their names,
 * declared units and baked-in values (declared units). */
int ccrt_num_errors(void);
const char* ccrt_error_name(int i);
const char* ccrt_error_unit(int i);
double ccrt_error_value(int i);
/* All errors at once (declared units, ccrt_num_errors() of them), allocation-free: checked
 * together and applied all or none (chaincompd's params updates: ParamsUpdater). -1 applied,
 * else the chaincomp::Refuse reason. */
int ccrt_set_errors(const double* values, long long utime_us);
/* The objective's direction weight (mm per rad, compensate.hpp) from the next step on: 0, or
 * -1 (unchanged) outside 0.1 .. 10000 mm. ccrt_direction_weight() is the one in use. */
int ccrt_set_direction_weight(double mm);
double ccrt_direction_weight(void);

#ifdef __cplusplus
}
#endif
#endif
