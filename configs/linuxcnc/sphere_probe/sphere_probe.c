/* sphere_probe: the simulated touch probe of chaincomp's LinuxCNC probing route (issue #45).
 * A realtime HAL component: each servo period it evaluates the *true* machine's tool point
 * (the machine file's exact model with the true errors baked in, sphere_probe_core.cpp) at
 * the drive positions and raises `touch` while that point is within `radius` (the sphere's
 * plus the stylus ball's) of the sphere's centre. Wired to motion.probe-input, G38.2 stops
 * where the true machine's stylus first touches the virtual sphere. In the servo thread, not
 * in a userspace loop: at a probing feed of 100 mm/min the tool moves 1.7 um a period, and a
 * userspace loop that stalls for tens of ms would put each touch tens of um late.
 *
 * Pins (N = joint, the machine file's axis order; LinuxCNC units: mm, deg):
 *   sphere-probe.joint.N.pos   float in   the drive position (offset.N.out: command + correction)
 *   sphere-probe.center-x/-y/-z float in  the sphere's true centre (mm, the machine file's base frame)
 *   sphere-probe.radius        float in   sphere radius + stylus ball radius (mm); 0: never touches
 *   sphere-probe.touch         bit out    the tool point is within radius of the centre
 *   sphere-probe.gap           float out  distance to the centre minus radius (mm)
 * Function: sphere-probe.update, after the drive positions are computed (offset.N.update-output).
 */
#include "rtapi.h"
#include "rtapi_app.h"
#include "rtapi_math.h"
#include "hal.h"

MODULE_AUTHOR("chaincomp");
MODULE_DESCRIPTION("simulated touch probe: the true machine's tool point against a virtual sphere");
MODULE_LICENSE("GPL");

#define SP_MAX_AXES 8

int sp_init(void);
int sp_num_axes(void);
void sp_tool_point(const double* joints, double* point);

struct sp_pins {
  hal_float_t *pos[SP_MAX_AXES];
  hal_float_t *center[3], *radius, *gap;
  hal_bit_t *touch;
};

static int comp_id, num_axes;
static struct sp_pins *pins;

static void update(void *arg, long period) {
  double q[SP_MAX_AXES], p[3], d2 = 0.0, r = *pins->radius;
  int i;
  (void)arg;
  (void)period;
  for (i = 0; i < num_axes; ++i) q[i] = *pins->pos[i];
  sp_tool_point(q, p);
  for (i = 0; i < 3; ++i) d2 += (p[i] - *pins->center[i]) * (p[i] - *pins->center[i]);
  *pins->gap = sqrt(d2) - r;
  *pins->touch = r > 0.0 && d2 <= r * r;
}

#define PIN(kind, dir, ptr, ...)                                              \
  do {                                                                        \
    if (hal_pin_##kind##_newf(dir, ptr, comp_id, __VA_ARGS__) != 0) goto fail; \
  } while (0)

int rtapi_app_main(void) {
  int i;
  comp_id = hal_init("sphere_probe");
  if (comp_id < 0) return comp_id;
  num_axes = sp_init();
  pins = hal_malloc(sizeof *pins);
  if (pins == 0 || num_axes < 1 || num_axes > SP_MAX_AXES) goto fail;
  for (i = 0; i < num_axes; ++i) PIN(float, HAL_IN, &pins->pos[i], "sphere-probe.joint.%d.pos", i);
  PIN(float, HAL_IN, &pins->center[0], "sphere-probe.center-x");
  PIN(float, HAL_IN, &pins->center[1], "sphere-probe.center-y");
  PIN(float, HAL_IN, &pins->center[2], "sphere-probe.center-z");
  PIN(float, HAL_IN, &pins->radius, "sphere-probe.radius");
  PIN(float, HAL_OUT, &pins->gap, "sphere-probe.gap");
  PIN(bit, HAL_OUT, &pins->touch, "sphere-probe.touch");
  *pins->radius = 0.0;
  *pins->touch = 0;
  if (hal_export_funct("sphere-probe.update", update, 0, 1, 0, comp_id) != 0) goto fail;
  hal_ready(comp_id);
  return 0;
fail:
  rtapi_print_msg(RTAPI_MSG_ERR, "sphere_probe: cannot export its pins or function\n");
  hal_exit(comp_id);
  return -EINVAL;
}

void rtapi_app_exit(void) { hal_exit(comp_id); }
