/* chaincomp_rt: realtime HAL component running one machine's generated compensation in the
 * servo thread. The HAL glue: pins, the thread function, the cost of each call. The model,
 * its params and chaincompd's ramp and limits are in the C++ core (chaincomp_rt_core.cpp),
 * set up at module load; the thread function allocates nothing.
 *
 * Pins (N = joint, in the machine file's axis order; LinuxCNC units: mm, deg; the prefix is
 * chaincomp-rt, or the module's name with - for _ when built with --name):
 *   chaincomp-rt.joint.N.pos-cmd     float in   commanded joint position (joint.N.motor-pos-cmd)
 *   chaincomp-rt.joint.N.correction  float out  correction to add to it (offset.N.offset)
 *   chaincomp-rt.enable              bit in     compensate; the correction ramps in and out
 *   chaincomp-rt.compensating        bit out    a correction is applied (or ramping out)
 *   chaincomp-rt.ramp                float out  0 (off) .. 1 (fully on)
 *   chaincomp-rt.clamped             bit out    the correction was limited in size or rate
 *   chaincomp-rt.fault               bit out    the last command was refused: the correction is held
 *   chaincomp-rt.reject-reason       s32 out    -1, or why the last command was refused (chaincompd's reasons)
 *   chaincomp-rt.rejected            s32 out    commands refused so far (the counters stop at 2^31-1)
 *   chaincomp-rt.status              s32 out    compensate's status of the last target (0 ok, 1 residual)
 *   chaincomp-rt.residual-point      float out  mm left at the last target (by the model)
 *   chaincomp-rt.cost-ns             s32 out    time of the last call (compensation included), ns
 *   chaincomp-rt.cost-max-ns         s32 out    largest cost-ns so far (write 0 to restart it)
 *   chaincomp-rt.error.NAME          float in   each constant error of the machine, in its declared unit (um,
 *                                               arcsec, ...), the params file's value at load
 *   chaincomp-rt.params-seq          s32 in     change it to apply every error pin at once (all or none); any
 *                                               change is a new set (a pin holds a level: nothing to reorder or
 *                                               replay, so no order to lock out; a restart from 1, a wrap)
 *   chaincomp-rt.params-version      s32 out    sets applied so far
 *   chaincomp-rt.params-refused      s32 out    sets refused so far
 *   chaincomp-rt.params-reason       s32 out    -1, or why the last set was refused (chaincompd's params reasons)
 * Parameter:
 *   chaincomp-rt.direction-weight    float rw   mm (0.1 .. 10000, default 100): the objective counts a direction
 *                                               error as at this length (chaincompd's direction_weight); a
 *                                               value outside is not taken (the parameter goes back)
 * Function: chaincomp-rt.update (floating point), between motion-controller and the offsets.
 */
#include "rtapi.h"
#include "rtapi_app.h"
#include "rtapi_math.h"
#include "hal.h"

#include "chaincomp_rt.h"
#include "chaincomp_rt_name.h" /* generated: CCRT_MODULE (loadrt name) and CCRT_PREFIX (pins) */

MODULE_AUTHOR("chaincomp");
MODULE_DESCRIPTION("chaincomp geometric error compensation in the servo thread");
MODULE_LICENSE("GPL");

#define CCRT_MAX_AXES 8
#define CCRT_MAX_ERRORS 64  /* chaincomp::kMaxUpdateValues */

struct ccrt_pins {
  hal_float_t *pos_cmd[CCRT_MAX_AXES];
  hal_float_t *correction[CCRT_MAX_AXES];
  hal_bit_t *enable, *compensating, *clamped, *fault;
  hal_float_t *ramp, *residual_point;
  hal_s32_t *reject_reason, *rejected, *status, *cost_ns, *cost_max_ns;
  hal_float_t *error[CCRT_MAX_ERRORS];
  hal_s32_t *params_seq, *params_version, *params_refused, *params_reason;
  hal_float_t direction_weight;  /* a parameter */
};

static int comp_id;
static struct ccrt_pins *pins;
static int num_axes, num_errors;
static hal_s32_t last_params_seq;
static long long utime_ns;  /* command time: the sum of the servo periods */

/* A counter pin one up, stopping at its largest value (s32 overflow is undefined). */
static void count(hal_s32_t *n) {
  if (*n < 0x7fffffff) *n += 1;
}

static void update(void *arg, long period) {
  double cmd[CCRT_MAX_AXES], corr[CCRT_MAX_AXES];
  struct ccrt_result r;
  long long start = rtapi_get_time(), cost;
  int i;
  (void)arg;
  utime_ns += period;
  if (*pins->params_seq != last_params_seq) {  /* a new set of errors: all of them, before this period's command */
    double values[CCRT_MAX_ERRORS];
    int reason;
    last_params_seq = *pins->params_seq;
    for (i = 0; i < num_errors; ++i) values[i] = *pins->error[i];
    reason = ccrt_set_errors(values, utime_ns / 1000);
    count(reason < 0 ? pins->params_version : pins->params_refused);
    *pins->params_reason = reason;
  }
  if (pins->direction_weight != ccrt_direction_weight() && ccrt_set_direction_weight(pins->direction_weight) != 0)
    pins->direction_weight = ccrt_direction_weight();  /* outside the range: not taken */
  for (i = 0; i < num_axes; ++i) cmd[i] = *pins->pos_cmd[i];
  if (ccrt_step(cmd, *pins->enable, utime_ns / 1000, corr, &r)) {
    for (i = 0; i < num_axes; ++i) *pins->correction[i] = corr[i];
    *pins->compensating = (r.flags & 1) != 0;
    *pins->clamped = (r.flags & 4) != 0;
    *pins->status = r.status;
    *pins->residual_point = r.residual_point;
    *pins->fault = 0;
  } else {
    *pins->fault = 1;  /* the last correction stays on the pins */
    count(pins->rejected);
  }
  *pins->reject_reason = r.reject;
  *pins->ramp = r.ramp;
  cost = rtapi_get_time() - start;
  if (cost > 0x7fffffff) cost = 0x7fffffff;
  *pins->cost_ns = (hal_s32_t)cost;
  if (*pins->cost_ns > *pins->cost_max_ns) *pins->cost_max_ns = *pins->cost_ns;
}

#define PIN(kind, dir, ptr, ...)                                              \
  do {                                                                        \
    if (hal_pin_##kind##_newf(dir, ptr, comp_id, __VA_ARGS__) != 0) goto fail; \
  } while (0)

int rtapi_app_main(void) {
  char error[256];
  int i;
  comp_id = hal_init(CCRT_MODULE);
  if (comp_id < 0) return comp_id;
  if (ccrt_init(error, sizeof error) != 0) {
    rtapi_print_msg(RTAPI_MSG_ERR, CCRT_MODULE ": %s\n", error);
    hal_exit(comp_id);
    return -EINVAL;
  }
  num_axes = ccrt_num_axes();
  pins = hal_malloc(sizeof *pins);
  if (pins == 0 || num_axes > CCRT_MAX_AXES) goto fail;
  for (i = 0; i < num_axes; ++i) {
    PIN(float, HAL_IN, &pins->pos_cmd[i], CCRT_PREFIX ".joint.%d.pos-cmd", i);
    PIN(float, HAL_OUT, &pins->correction[i], CCRT_PREFIX ".joint.%d.correction", i);
    *pins->correction[i] = 0.0;
  }
  PIN(bit, HAL_IN, &pins->enable, CCRT_PREFIX ".enable");
  PIN(bit, HAL_OUT, &pins->compensating, CCRT_PREFIX ".compensating");
  PIN(bit, HAL_OUT, &pins->clamped, CCRT_PREFIX ".clamped");
  PIN(bit, HAL_OUT, &pins->fault, CCRT_PREFIX ".fault");
  PIN(float, HAL_OUT, &pins->ramp, CCRT_PREFIX ".ramp");
  PIN(float, HAL_OUT, &pins->residual_point, CCRT_PREFIX ".residual-point");
  PIN(s32, HAL_OUT, &pins->reject_reason, CCRT_PREFIX ".reject-reason");
  PIN(s32, HAL_OUT, &pins->rejected, CCRT_PREFIX ".rejected");
  PIN(s32, HAL_OUT, &pins->status, CCRT_PREFIX ".status");
  PIN(s32, HAL_OUT, &pins->cost_ns, CCRT_PREFIX ".cost-ns");
  PIN(s32, HAL_IO, &pins->cost_max_ns, CCRT_PREFIX ".cost-max-ns");
  *pins->reject_reason = -1;
  num_errors = ccrt_num_errors();
  if (num_errors > CCRT_MAX_ERRORS) goto fail;
  for (i = 0; i < num_errors; ++i) {
    PIN(float, HAL_IN, &pins->error[i], CCRT_PREFIX ".error.%s", ccrt_error_name(i));
    *pins->error[i] = ccrt_error_value(i);
  }
  PIN(s32, HAL_IN, &pins->params_seq, CCRT_PREFIX ".params-seq");
  PIN(s32, HAL_OUT, &pins->params_version, CCRT_PREFIX ".params-version");
  PIN(s32, HAL_OUT, &pins->params_refused, CCRT_PREFIX ".params-refused");
  PIN(s32, HAL_OUT, &pins->params_reason, CCRT_PREFIX ".params-reason");
  *pins->params_seq = 0;
  last_params_seq = 0;
  *pins->params_reason = -1;
  if (hal_param_float_newf(HAL_RW, &pins->direction_weight, comp_id, CCRT_PREFIX ".direction-weight") != 0) goto fail;
  pins->direction_weight = ccrt_direction_weight();
  if (hal_export_funct(CCRT_PREFIX ".update", update, 0, 1, 0, comp_id) != 0) goto fail;
  rtapi_print_msg(RTAPI_MSG_INFO, CCRT_MODULE ": machine %s, %d joints, params %s\n", ccrt_machine(), num_axes,
                  ccrt_params_file());
  hal_ready(comp_id);
  return 0;
fail:
  rtapi_print_msg(RTAPI_MSG_ERR, CCRT_MODULE ": cannot export its pins or function\n");
  ccrt_fini();
  hal_exit(comp_id);
  return -EINVAL;
}

void rtapi_app_exit(void) {
  ccrt_fini();
  hal_exit(comp_id);
}
