/* gl: the window, the OpenGL context and MuJoCo's renderer around them (view.h).
 *
 * Frames are always rendered into MuJoCo's offscreen buffer at the requested size, then
 * read back (recording, screenshots) and, with a visible window, blitted to it: what is
 * recorded does not depend on the window's size, on it being covered, or on there being a
 * visible window at all. A hidden GLFW window only provides the context (NOTES.md: what
 * works under Xvfb). Mouse and keys as in MuJoCo's sample viewer (basic.cc). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <GL/gl.h>

#include "view.h"

#define MAXGEOM 2000  /* the scene's model geoms plus ours (draw.c adds a few hundred) */

static char glfw_why[256];

static void on_glfw_error(int code, const char *desc) {
  snprintf(glfw_why, sizeof glfw_why, "%s (GLFW error 0x%x)", desc, code);
}

/* Said whenever no context can be had: the usual cause and how to get a video anyway. */
#define NO_DISPLAY_HINT                                                                  \
  "nudge-view draws with OpenGL on an X server. Over SSH or in CI, run it on a virtual "  \
  "one, e.g.: xvfb-run -a nudge-view --hidden --record out.mp4 --seconds 10 (Debian: "    \
  "apt-get install xvfb xauth ffmpeg)"

static view_gl *gl_of(GLFWwindow *w) { return glfwGetWindowUserPointer(w); }

/* The drag starts where the last motion event left the cursor: glfwGetCursorPos would ask
 * the server for where it is now, past motion still queued behind the press. */
static void on_button(GLFWwindow *w, int button, int act, int mods) {
  (void)button;
  (void)act;
  (void)mods;
  view_gl *g = gl_of(w);
  g->btn_left = glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS;
  g->btn_right = glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS;
  g->btn_middle = glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_MIDDLE) == GLFW_PRESS;
}

/* Left drag rotates, right drag moves, middle drag zooms; shift: in the horizontal plane. */
static void on_move(GLFWwindow *w, double x, double y) {
  view_gl *g = gl_of(w);
  const double dx = x - g->lastx, dy = y - g->lasty;
  g->lastx = x;
  g->lasty = y;
  if (!g->btn_left && !g->btn_right && !g->btn_middle) return;
  int width, height;
  glfwGetWindowSize(w, &width, &height);
  if (height < 1) return;
  const int shift = glfwGetKey(w, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS ||
                    glfwGetKey(w, GLFW_KEY_RIGHT_SHIFT) == GLFW_PRESS;
  int action = mjMOUSE_ZOOM;
  if (g->btn_right) action = shift ? mjMOUSE_MOVE_H : mjMOUSE_MOVE_V;
  else if (g->btn_left) action = shift ? mjMOUSE_ROTATE_H : mjMOUSE_ROTATE_V;
  mjv_moveCamera(g->m, action, dx / height, dy / height, &g->scn, &g->cam);
}

static void on_scroll(GLFWwindow *w, double xoff, double yoff) {
  (void)xoff;
  view_gl *g = gl_of(w);
  mjv_moveCamera(g->m, mjMOUSE_ZOOM, 0, -0.05 * yoff, &g->scn, &g->cam);
}

/* R: back to the starting camera; Escape or Q: close. */
static void on_key(GLFWwindow *w, int key, int scancode, int act, int mods) {
  (void)scancode;
  (void)mods;
  if (act != GLFW_PRESS) return;
  view_gl *g = gl_of(w);
  if (key == GLFW_KEY_R) g->cam = g->cam0;
  if (key == GLFW_KEY_ESCAPE || key == GLFW_KEY_Q) glfwSetWindowShouldClose(w, 1);
}

int view_gl_init(view_gl *g, const mjModel *m, int w, int h, int visible,
                 const view_camera *cam, char *err, int errlen) {
  memset(g, 0, sizeof(*g));
  mjv_defaultScene(&g->scn);
  mjr_defaultContext(&g->con);
  g->m = m;
  g->w = w;
  g->h = h;
  g->visible = visible;
  const char *display = getenv("DISPLAY");
  if (!display || !*display) {
    snprintf(err, errlen, "no display (DISPLAY is not set). " NO_DISPLAY_HINT);
    return -1;
  }
  glfwSetErrorCallback(on_glfw_error);
  if (!glfwInit()) {
    snprintf(err, errlen, "cannot open display '%s': %s. " NO_DISPLAY_HINT, display, glfw_why);
    return -1;
  }
  glfwWindowHint(GLFW_VISIBLE, visible ? GLFW_TRUE : GLFW_FALSE);
  if (!(g->win = glfwCreateWindow(w, h, PROG, NULL, NULL))) {
    snprintf(err, errlen, "no OpenGL window on display '%s': %s. " NO_DISPLAY_HINT, display,
             glfw_why);
    return -1;
  }
  glfwMakeContextCurrent(g->win);
  glfwSwapInterval(0);  /* the frame loop keeps time; vsync would stall it */
  if (!(g->rgb = malloc((size_t)w * h * 3))) {
    snprintf(err, errlen, "out of memory for a %dx%d frame", w, h);
    return -1;
  }
  mjv_defaultOption(&g->opt);
  mjv_defaultCamera(&g->cam);
  g->cam.type = mjCAMERA_FREE;
  for (int k = 0; k < 3; k++) g->cam.lookat[k] = cam->lookat[k];
  g->cam.distance = cam->distance;
  g->cam.azimuth = cam->azimuth;
  g->cam.elevation = cam->elevation;
  g->cam0 = g->cam;
  mjv_makeScene(m, &g->scn, MAXGEOM);
  mjr_makeContext(m, &g->con, h >= 600 ? mjFONTSCALE_150 : mjFONTSCALE_100);
  if (g->con.offWidth < w || g->con.offHeight < h) {
    snprintf(err, errlen, "the OpenGL driver gave an offscreen buffer of %dx%d, not %dx%d",
             g->con.offWidth, g->con.offHeight, w, h);
    return -1;
  }
  mjr_setBuffer(mjFB_OFFSCREEN, &g->con);
  if (g->con.currentBuffer != mjFB_OFFSCREEN) {
    snprintf(err, errlen, "the OpenGL driver offers no offscreen framebuffer");
    return -1;
  }
  if (view_text_init(&g->text, &g->con, w, h, err, errlen)) return -1;
  glfwSetWindowUserPointer(g->win, g);
  if (visible) {
    glfwSetMouseButtonCallback(g->win, on_button);
    glfwSetCursorPosCallback(g->win, on_move);
    glfwSetScrollCallback(g->win, on_scroll);
    glfwSetKeyCallback(g->win, on_key);
    glfwGetCursorPos(g->win, &g->lastx, &g->lasty);
  }
  return 0;
}

const char *view_gl_renderer(void) {
  const GLubyte *r = glGetString(GL_RENDERER);
  return r ? (const char *)r : "unknown";
}

mjrRect view_gl_viewport(const view_gl *g) {
  mjrRect r = {0, 0, g->w, g->h};
  return r;
}

void view_gl_scene(view_gl *g, const mjModel *m, mjData *d) {
  mjv_updateScene(m, d, &g->opt, NULL, &g->cam, mjCAT_ALL, &g->scn);
}

void view_gl_render(view_gl *g) {
  mjr_setBuffer(mjFB_OFFSCREEN, &g->con);
  mjr_render(view_gl_viewport(g), &g->scn, &g->con);
}

void view_gl_finish(view_gl *g, int read) {
  const mjrRect vp = view_gl_viewport(g);
  /* Each frame ends finished: a reading or glFinish. Mesa frees what a frame's text drew
   * with (mjr_overlay's bitmaps) only once the frame has run; unsynced frames grew the
   * heap by ~20 MB/s at 30 fps. It also makes a frame's work time its real cost. */
  if (read) mjr_readPixels(g->rgb, NULL, vp, &g->con);
  else glFinish();
  if (!g->visible) return;
  int fw, fh;
  glfwGetFramebufferSize(g->win, &fw, &fh);
  const mjrRect dst = {0, 0, fw, fh};
  mjr_blitBuffer(vp, dst, 1, 0, &g->con);  /* offscreen to the window */
  glfwSwapBuffers(g->win);
}

int view_gl_poll(view_gl *g) {
  if (!g->win) return 0;
  glfwPollEvents();
  return glfwWindowShouldClose(g->win);
}

void view_gl_free(view_gl *g) {
  if (g->win) {
    glfwMakeContextCurrent(g->win);
    view_text_free(&g->text);
    mjr_freeContext(&g->con);
    mjv_freeScene(&g->scn);
    glfwDestroyWindow(g->win);
  }
  glfwTerminate();
  free(g->rgb);
  memset(g, 0, sizeof(*g));
}
