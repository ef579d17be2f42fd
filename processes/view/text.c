/* text: the overlay's text from one texture (view.h).
 *
 * MuJoCo draws text with display lists of glBitmap calls, one per character; software
 * OpenGL (llvmpipe, the renderer under Xvfb) turns each into a textured draw of its own,
 * and the overlay's ~400 characters cost ~8 ms a frame, as much as the whole scene. So the
 * glyphs of MuJoCo's normal font are drawn once, at start, into the offscreen buffer, read
 * back into an alpha atlas, and each frame's text is one batch of textured quads from it:
 * the same font, placed as MuJoCo's raster positions place it. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <GL/gl.h>

#include "view.h"

#define FIRST 32      /* ' ' */
#define NCHARS VIEW_TEXT_NCHARS
#define COLS 16
#define ROWS ((NCHARS + COLS - 1) / COLS)
#define PAD 4         /* px of cell around a glyph's advance: kerning and overhang */

int view_text_init(view_text *t, mjrContext *con, int w, int h, char *err, int errlen) {
  memset(t, 0, sizeof(*t));
  int adv = 0;
  for (int c = FIRST; c < FIRST + NCHARS; c++)
    if (con->charWidth[c] > adv) adv = con->charWidth[c];
  t->cw = adv + 2 * PAD;
  t->ch = 3 * con->charHeight; /* the raster position a third of the way up */
  t->line = con->charHeight;
  for (int c = 0; c < 128; c++) t->adv[c] = c >= FIRST && c < FIRST + NCHARS ? con->charWidth[c] : 0;
  t->tw = COLS * t->cw;
  t->th = ROWS * t->ch;
  if (t->tw > w || t->ch > h) return 0; /* too small a frame for a row of cells: MuJoCo's text */
  unsigned char *rgb = malloc((size_t)w * h * 3), *alpha = calloc((size_t)t->tw * t->th, 1);
  if (!rgb || !alpha) {
    free(rgb);
    free(alpha);
    snprintf(err, errlen, "out of memory for the text atlas");
    return -1;
  }
  const mjrRect vp = {0, 0, w, h};
  mjr_setBuffer(mjFB_OFFSCREEN, con);
  for (int row = 0; row < ROWS; row++) {
    glViewport(0, 0, w, h);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_LIGHTING);
    glDisable(GL_TEXTURE_2D);
    glDisable(GL_BLEND);
    glClearColor(0, 0, 0, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    glMatrixMode(GL_PROJECTION);
    glLoadIdentity();
    glOrtho(0, w, 0, h, -1, 1);
    glMatrixMode(GL_MODELVIEW);
    glLoadIdentity();
    glColor4f(1, 1, 1, 1);
    glListBase(con->baseFontNormal);
    for (int k = 0; k < COLS; k++) {
      const unsigned char c = (unsigned char)(FIRST + row * COLS + k);
      if (c >= FIRST + NCHARS) break;
      glRasterPos2i(k * t->cw + PAD, t->line);
      glCallLists(1, GL_UNSIGNED_BYTE, &c);
    }
    mjr_readPixels(rgb, NULL, vp, con); /* resolves a multisampled buffer */
    for (int y = 0; y < t->ch; y++)
      for (int x = 0; x < t->tw; x++)
        alpha[(size_t)(row * t->ch + y) * t->tw + x] = rgb[((size_t)y * w + x) * 3];
  }
  /* Each glyph's inked box in its cell: the quads cover only that (software OpenGL pays
   * per fragment, and a cell is mostly empty). */
  for (int i = 0; i < NCHARS; i++) {
    const int u = (i % COLS) * t->cw, v = (i / COLS) * t->ch;
    int x0 = t->cw, x1 = -1, y0 = t->ch, y1 = -1;
    for (int y = 0; y < t->ch; y++)
      for (int x = 0; x < t->cw; x++)
        if (alpha[(size_t)(v + y) * t->tw + u + x]) {
          if (x < x0) x0 = x;
          if (x > x1) x1 = x;
          if (y < y0) y0 = y;
          if (y > y1) y1 = y;
        }
    view_text_box *b = &t->box[i];
    if (x1 < 0) b->w = b->h = 0;
    else b->x = x0, b->y = y0, b->w = x1 - x0 + 1, b->h = y1 - y0 + 1;
  }
  glGenTextures(1, &t->tex);
  glBindTexture(GL_TEXTURE_2D, t->tex);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_ALPHA, t->tw, t->th, 0, GL_ALPHA, GL_UNSIGNED_BYTE, alpha);
  glBindTexture(GL_TEXTURE_2D, 0);
  free(rgb);
  free(alpha);
  if (glGetError() != GL_NO_ERROR) {
    snprintf(err, errlen, "the OpenGL driver refused the text atlas (%dx%d)", t->tw, t->th);
    return -1;
  }
  return 0;
}

void view_text_free(view_text *t) {
  if (t->tex) glDeleteTextures(1, &t->tex);
  memset(t, 0, sizeof(*t));
}

/* Width of line s (up to '\n' or the end) in pixels, and where it ends. */
static int line_width(const view_text *t, const char *s, const char **end) {
  int w = 0;
  for (; *s && *s != '\n'; s++) {
    const int c = (unsigned char)*s;
    if (c < 128) w += t->adv[c];  /* 0 for what has no glyph, as put_line skips it */
  }
  *end = s;
  return w;
}

/* The widest line of s, and its number of lines. */
static int measure(const view_text *t, const char *s, int *rows) {
  int w = 0;
  *rows = 0;
  for (;;) {
    const char *e;
    const int lw = line_width(t, s, &e);
    if (lw > w) w = lw;
    (*rows)++;
    if (!*e) return w;
    s = e + 1;
  }
}

/* Quads for the line s..e with its raster position at (x, y). */
static void put_line(const view_text *t, const char *s, const char *e, int x, int y) {
  const float sw = 1.0f / t->tw, sh = 1.0f / t->th;
  for (; s < e; s++) {
    const int c = (unsigned char)*s;
    if (c < FIRST || c >= FIRST + NCHARS) continue;
    const int i = c - FIRST;
    const view_text_box *b = &t->box[i];
    if (b->w) {
      const int u = (i % COLS) * t->cw + b->x, v = (i / COLS) * t->ch + b->y;
      const int x0 = x - PAD + b->x, y0 = y - t->line + b->y;
      glTexCoord2f(u * sw, v * sh);
      glVertex2i(x0, y0);
      glTexCoord2f((u + b->w) * sw, v * sh);
      glVertex2i(x0 + b->w, y0);
      glTexCoord2f((u + b->w) * sw, (v + b->h) * sh);
      glVertex2i(x0 + b->w, y0 + b->h);
      glTexCoord2f(u * sw, (v + b->h) * sh);
      glVertex2i(x0, y0 + b->h);
    }
    x += t->adv[c];
  }
}

void view_text_block(const view_text *t, mjrRect vp, int right, const char *keys,
                     const char *values) {
  /* Columns: keys, a gap, values; one row per line of either, top down. */
  int krows, vrows;
  const int kw = measure(t, keys, &krows), vw = measure(t, values, &vrows);
  const int rows = krows > vrows ? krows : vrows;
  const int margin = t->line / 2, gap = 2 * t->adv[' '], step = t->line + t->line / 4;
  const int bw = kw + gap + vw + 2 * margin, bh = rows * step + margin;
  const int bx = right ? vp.left + vp.width - bw : vp.left, btop = vp.bottom + vp.height;

  /* Whatever state mjr_render left (texture units, coordinate generation, culling) is
   * put back after the block. */
  glPushAttrib(GL_ALL_ATTRIB_BITS);
  glActiveTexture(GL_TEXTURE0);
  glDisable(GL_TEXTURE_GEN_S);
  glDisable(GL_TEXTURE_GEN_T);
  glDisable(GL_TEXTURE_GEN_R);
  glDisable(GL_TEXTURE_GEN_Q);
  glDisable(GL_CULL_FACE);
  glDisable(GL_ALPHA_TEST);
  glDisable(GL_FOG);
  glDisable(GL_STENCIL_TEST);
  glDisable(GL_SCISSOR_TEST);
  glMatrixMode(GL_TEXTURE);
  glLoadIdentity();
  glViewport(vp.left, vp.bottom, vp.width, vp.height);
  glMatrixMode(GL_PROJECTION);
  glLoadIdentity();
  glOrtho(vp.left, vp.left + vp.width, vp.bottom, vp.bottom + vp.height, -1, 1);
  glMatrixMode(GL_MODELVIEW);
  glLoadIdentity();
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_LIGHTING);
  glEnable(GL_BLEND);
  glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
  glDisable(GL_TEXTURE_2D);
  glColor4f(0, 0, 0, 0.4f);
  glRecti(bx, btop - bh, bx + bw, btop);

  glEnable(GL_TEXTURE_2D);
  glBindTexture(GL_TEXTURE_2D, t->tex);
  glTexEnvi(GL_TEXTURE_ENV, GL_TEXTURE_ENV_MODE, GL_MODULATE);
  glBegin(GL_QUADS);
  for (int col = 0; col < 2; col++) {
    const char *s = col ? values : keys;
    if (col) glColor4f(1.0f, 1.0f, 1.0f, 1.0f);
    else glColor4f(0.75f, 0.85f, 1.0f, 1.0f);
    const int x = bx + margin + (col ? kw + gap : 0);
    for (int r = 0;; r++) {
      const char *e;
      line_width(t, s, &e);
      put_line(t, s, e, x, btop - (r + 1) * step);
      if (!*e) break;
      s = e + 1;
    }
  }
  glEnd();
  glBindTexture(GL_TEXTURE_2D, 0);
  glPopAttrib();
}
