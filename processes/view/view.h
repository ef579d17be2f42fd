/* view: what the files of nudge-view share.
 *
 *   main.c     wiring: set-up, tear-down, the figures printed at exit
 *   options.c  the command line
 *   run.c      the frame loop: frames timed live or by a log's timestamps, MP4 and PNG out
 *   inputs.c   the input channels: validation, counting, the newest of each kind
 *   scene.c    the world as a MuJoCo model (one function per world kind), posed from inputs
 *   draw.c     what the model does not hold, as geoms in the mjvScene: goal and predicted
 *              ghosts, the plan's keypoints and minimum-snap path, the setpoint trail
 *   overlay.c  the text: task, error against eps, plans/s, theta, heartbeats
 *   gl.c       GLFW window and OpenGL context, MuJoCo's render context, mouse camera,
 *              rendering a frame offscreen and reading it back
 *   ffmpeg.c   frames out through ffmpeg children: an MP4 stream, PNG screenshots
 *   logplay.c  an lcm-logger log, its events handed on up to each frame's time
 *
 * Everything runs on the main thread; memory is allocated at start-up and freed at exit.
 * View time is microseconds on the senders' wall clock: live, ndp_utime(); from a log,
 * the frame's time on the log's timestamps. Nothing drawn depends on the wall clock
 * otherwise, so the same inputs give the same pixels. */
#ifndef VIEW_H
#define VIEW_H

#include <GLFW/glfw3.h>
#include <lcm/eventlog.h>
#include <mujoco/mujoco.h>
#include <sys/types.h>

#include "nd_jitter.h"
#include "ndp.h"
#include "ndp_validate.h"
#include "nds_model.h"
#include "nds_panda.h"
#include "nds_world.h"

#define PROG "nudge-view"

/* ---- inputs.c ---------------------------------------------------------------------- */

enum { VIEW_WORLD_IDEAL = 0, VIEW_WORLD_LAB = 1 };

enum { VIEW_CH_MOCAP, VIEW_CH_TASK, VIEW_CH_PLAN, VIEW_CH_EE_CMD, VIEW_CH_PARAMS,
       VIEW_CH_STATUS, VIEW_CH_EPISODE, VIEW_CH_ARM_STATE, VIEW_NCH };

#define VIEW_TEXT 64         /* status_t's name and state are shorter (its contract) */
#define VIEW_REASON 256      /* episode_t's reason is shorter */
#define VIEW_MAX_PROCS 16    /* heartbeats shown; the oldest gives way to a new name */
#define VIEW_TRAIL_CAP 512   /* setpoints kept for the trail (decimated) */
#define VIEW_TRAIL_DT 0.02   /* s of EE_CMD time between trail points */
#define VIEW_RATE_CAP 128    /* PLAN arrivals kept for plans/s */
#define VIEW_RATE_WINDOW 2.0 /* s over which plans/s is counted */

typedef struct {
  char name[VIEW_TEXT], state[VIEW_TEXT];
  int32_t pid;
  int64_t utime;   /* the heartbeat's own stamp */
  int64_t rejected;
} view_beat;

typedef struct {
  double p[3];
  int64_t utime;
} view_trail_pt;

typedef struct {
  ndp_status st;
  ndp_ratelog refused[VIEW_NCH];
  double trail_s;             /* trail length, s of EE_CMD time */
  int64_t log_us;             /* while a log's event is handed on: its time; else 0 (live) */

  int have_mocap, have_task, have_plan, have_cmd, have_params, have_episode, have_arm;
  nudge_mocap_t mocap;
  nudge_task_t task;
  nudge_plan_t plan;
  /* The plan's start state, like the executor's at the plan's arrival: the newest setpoint
   * (p, v, a; jerk 0) if one came, else the sphere at rest where MOCAP saw it, else the
   * first keypoint. seg0_T is segment 0's duration shortened by the plan's age, as
   * nudge-executor shortens it (exec_io.c). */
  double plan_s0[2][4];
  double plan_seg0_T;
  nudge_ee_cmd_t cmd;
  view_trail_pt trail[VIEW_TRAIL_CAP];
  int trail_head, trail_n;    /* ring: trail[(trail_head - 1) mod CAP] is the newest */
  int64_t plan_arrivals[VIEW_RATE_CAP];
  int plan_head, plan_n;
  nudge_params_t params;
  view_beat procs[VIEW_MAX_PROCS];
  int nprocs;
  int64_t ep_task_id, ep_utime;
  int8_t ep_event;
  double ep_time, ep_error;
  char ep_reason[VIEW_REASON];
  double arm_q[NDS_PANDA_NJ];
} view_inputs;

/* Zero in and start its heartbeat (STATUS name nudge-view). */
void view_inputs_init(view_inputs *in, double trail_s);

/* The name of channel VIEW_CH_k. */
const char *view_channel(int k);

/* Subscribe every input channel on lcm. Return 0, or -1 with a message. */
int view_inputs_subscribe(view_inputs *in, lcm_t *lcm, char *err, int errlen);

/* Hand one message of channel (a log's event) to the handler a subscription would call,
 * received at recv_utime. Channels the view does not read are ignored. */
void view_inputs_dispatch(view_inputs *in, const char *channel, const void *data, int size,
                          int64_t recv_utime);

/* PLAN arrivals per second over the VIEW_RATE_WINDOW before now_us. */
double view_inputs_plan_rate(const view_inputs *in, int64_t now_us);

/* ---- scene.c ----------------------------------------------------------------------- */

typedef struct {
  int world;
  mjModel *m;                 /* owned: nm.m (ideal) or the panda scene (lab) */
  mjData *d;
  nds_model nm;               /* ideal: the project's scene (nds_model.h) */
  nds_panda arm;              /* lab: the arm in m (its rest posture is shown until the
                                 first ARM_STATE) */
  int obj_qpos, obj_geom;     /* the box's free joint and geom */
  int ee_qpos[2], ee_geom;    /* ideal: the sphere's slide joints and geom; lab: -1 */
  double obj_half[3], ee_radius, ee_height;
} view_scene;

/* Build the scene of world (VIEW_WORLD_*) with an offscreen buffer of w x h pixels and
 * samples-fold multisampling; colours set for drawing. Return 0, or -1 with a message. */
int view_scene_init(view_scene *s, int world, int w, int h, int samples, char *err,
                    int errlen);

/* Pose the model from the newest inputs (object and sphere from MOCAP, arm from ARM_STATE)
 * and run mj_kinematics. */
void view_scene_pose(view_scene *s, const view_inputs *in);

/* Drop from scn the model geoms nothing has placed yet: the object and the ideal world's
 * sphere before the first MOCAP. */
void view_scene_hide_unseen(const view_scene *s, const view_inputs *in, mjvScene *scn);

void view_scene_free(view_scene *s);

/* ---- draw.c ------------------------------------------------------------------------ */

/* Append the goal ghost, the predicted-pose ghost, the plan's keypoints and minimum-snap
 * path, and the setpoint trail to scn (as many as scn->maxgeom leaves room for). Return
 * the number of geoms that did not fit. */
int view_draw(const view_scene *s, const view_inputs *in, mjvScene *scn);

/* ---- text.c ------------------------------------------------------------------------ */

/* MuJoCo's normal font as one alpha texture of glyph cells (tex 0: not built, the frame
 * too small for a row of cells; the overlay then uses MuJoCo's own text). */
#define VIEW_TEXT_NCHARS 95 /* the glyphs ' ' .. '~' */

typedef struct {
  int x, y, w, h;     /* a glyph's inked pixels in its cell (w 0: none) */
} view_text_box;

typedef struct {
  unsigned int tex;
  view_text_box box[VIEW_TEXT_NCHARS];
  int cw, ch, line;   /* cell size; the raster position is `line` px up the cell */
  int tw, th;         /* the texture's size */
  int adv[128];       /* advance per character, px */
} view_text;

/* Capture the glyphs of con's normal font through its offscreen buffer (w x h, cleared:
 * call before the first frame). 0, or -1 with a message. */
int view_text_init(view_text *t, mjrContext *con, int w, int h, char *err, int errlen);
void view_text_free(view_text *t);

/* Two columns of '\n'-separated lines, keys and values, on a dark band at the top left
 * (right 0) or top right of vp. */
void view_text_block(const view_text *t, mjrRect vp, int right, const char *keys,
                     const char *values);

/* ---- overlay.c --------------------------------------------------------------------- */

/* Draw the text over the frame in viewport vp: with t's atlas, else MuJoCo's text. */
void view_overlay(const view_inputs *in, int64_t now_us, mjrRect vp, const mjrContext *con,
                  const view_text *t);

/* ---- gl.c -------------------------------------------------------------------------- */

typedef struct {
  GLFWwindow *win;
  int visible, w, h;
  mjvScene scn;
  mjvCamera cam, cam0;        /* cam0: the camera to reset to (key R) */
  mjvOption opt;
  mjrContext con;
  view_text text;
  const mjModel *m;
  unsigned char *rgb;         /* w * h * 3, rows bottom-up as mjr_readPixels gives them */
  int btn_left, btn_right, btn_middle;
  double lastx, lasty;
} view_gl;

/* The camera: lookat x, y, z (m), distance (m), azimuth, elevation (degrees). */
typedef struct {
  double lookat[3], distance, azimuth, elevation;
} view_camera;

/* Open a window (shown if visible, else hidden: rendering is offscreen either way) with an
 * OpenGL context for model m, whose offscreen buffer is w x h. Return 0, or -1 with a
 * message that says how to get a video without a display. */
int view_gl_init(view_gl *g, const mjModel *m, int w, int h, int visible,
                 const view_camera *cam, char *err, int errlen);

/* The OpenGL renderer's name (e.g. "llvmpipe (LLVM 15.0.6, 256 bits)": software). */
const char *view_gl_renderer(void);

/* Build the scene from m, d (mjv_updateScene) for the caller to add geoms to. */
void view_gl_scene(view_gl *g, const mjModel *m, mjData *d);

/* Render scn offscreen; the caller draws the overlay next into view_gl_viewport. */
void view_gl_render(view_gl *g);
mjrRect view_gl_viewport(const view_gl *g);

/* Read the frame into g->rgb; show it in the window if visible. read: 0 skips reading. */
void view_gl_finish(view_gl *g, int read);

/* Handle window events (mouse camera, keys). Return 1 if the window was closed. */
int view_gl_poll(view_gl *g);

void view_gl_free(view_gl *g);

/* ---- ffmpeg.c ---------------------------------------------------------------------- */

typedef struct {
  pid_t pid;                  /* 0: not running */
  int fd;                     /* the pipe to its stdin */
  int w, h;
  unsigned char *rows;        /* one frame top-down, for the write */
  const char *out;
} view_ffmpeg;

/* 0 if ffmpeg can be run from PATH, else -1 with a message saying how to install it. */
int view_ffmpeg_check(char *err, int errlen);

/* Start ffmpeg encoding w x h rgb24 frames at fps into an MP4 file out. Return 0, or -1. */
int view_ffmpeg_mp4(view_ffmpeg *f, const char *out, int w, int h, int fps, char *err,
                    int errlen);

/* Send one frame, rows bottom-up (mjr_readPixels). Return 0, or -1 (ffmpeg died). */
int view_ffmpeg_frame(view_ffmpeg *f, const unsigned char *rgb, char *err, int errlen);

/* Close the pipe and wait for ffmpeg to finish the file. Return 0, or -1 if it failed. */
int view_ffmpeg_close(view_ffmpeg *f, char *err, int errlen);

/* Write one frame (rows bottom-up) as the PNG file out, through a one-frame ffmpeg into a
 * temporary name renamed into place, so a reader never sees half a file. rows is scratch
 * of w * h * 3 bytes. Return 0, or -1. */
int view_png(const char *out, const unsigned char *rgb, int w, int h, unsigned char *rows,
             char *err, int errlen);

/* ---- logplay.c --------------------------------------------------------------------- */

typedef struct {
  lcm_eventlog_t *log;
  lcm_eventlog_event_t *next; /* read ahead: the first event not yet handed on */
  int64_t t0;                 /* the first event's timestamp, us */
  int64_t t_last;             /* the newest timestamp handed on, us */
  int64_t events;             /* events handed on */
} view_log;

/* Open path and read its first event. Return 0, or -1 (unreadable or empty). */
int view_log_open(view_log *l, const char *path, char *err, int errlen);

/* Hand every event stamped at or before t_us to the inputs. Return 1 while events remain
 * after t_us, 0 once the log is exhausted. */
int view_log_feed(view_log *l, view_inputs *in, int64_t t_us);

void view_log_close(view_log *l);

/* ---- run.c ------------------------------------------------------------------------- */

/* What nudge-view was asked to do; constant once parsed. */
typedef struct {
  const char *url, *record, *png, *log;
  double png_at;              /* s of view time; < 0: at exit */
  double speed;               /* log: 1 = real time, 0 = as fast as it can */
  double seconds;             /* > 0: end after this much view time */
  double trail;               /* s of setpoints drawn */
  int w, h, fps, samples, hidden, world, no_overlay, nice;
  view_camera cam;
} view_opts;

/* Names of the worlds, by VIEW_WORLD_*, NULL-terminated. */
extern const char *const view_worlds[];

/* options.c: parse argv into o. ND_OPT_RUN, or the exit status (usage or refusal printed). */
int view_options(int argc, char **argv, view_opts *o);

/* The program's parts, owned here, built by main.c. */
typedef struct {
  const view_opts *o;
  view_inputs in;
  view_scene sc;
  view_gl g;
  view_ffmpeg rec;            /* recording while rec.pid != 0 */
  view_log lg;                /* with --log */
  lcm_t *lcm;                 /* live input and the heartbeat; NULL from a log if LCM
                                 could not be opened (no heartbeat then) */
  unsigned char *rows;        /* scratch for PNG writes */
  int png_done;
  int64_t last_us;            /* view time of the newest frame */
  /* figures */
  int64_t frames;             /* frames of view time shown (recorded, with repeats) */
  int64_t renders, late, dropped;
  nd_jitter lateness, work;   /* frame start after its due time; one frame's work, us */
  double work_s;              /* all frames' work, s */
  nd_rtloop_stats loop;       /* the heartbeat's view of lateness */
  double t0, t1;              /* ndp_mono() at the loop's start and end */
} view_app;

/* Run frames until the end (--seconds, the log's end, SIGINT/SIGTERM, the window closed),
 * then finish the MP4 and the PNG at exit. SIGUSR1 writes the --png file at the next
 * frame. Return 0, or -1 with a message (ffmpeg or LCM failed). */
int view_run(view_app *v, char *err, int errlen);

#endif
