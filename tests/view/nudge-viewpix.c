/* nudge-viewpix: measures frames for nudge-view's tests (a test helper, not installed).
 * Frames are binary PPM (P6, 8 bits), as `ffmpeg -i frame.png frame.ppm` writes them.
 *
 *   nudge-viewpix blob FILE COLOUR [X0 Y0 X1 Y1]
 *       pixels of a colour class (in the rectangle, pixel coordinates, x right, y down):
 *       'blob_n N count', 'blob_x X px', 'blob_y Y px' (the centroid; -1 if none)
 *   nudge-viewpix diff A B
 *       'diff_pixels N count' (pixels that differ at all), 'diff_max M level'
 *   nudge-viewpix at FILE X Y
 *       'rgb R G B' of one pixel
 *
 * Colour classes, for what nudge-view draws (scene.c, draw.c) under its lighting:
 *   blue    the box            green   the goal ghost       orange  the predicted ghost
 *   red     the sphere         yellow  keypoints and path   cyan    the setpoint trail
 *   white   the overlay's text
 * Exit status 0, 1 if a file is not a P6 PPM, 2 on bad usage. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
  int w, h;
  unsigned char *px;  /* w * h * 3, rows top-down */
} image;

static int load(const char *path, image *im) {
  FILE *f = fopen(path, "rb");
  int maxv = 0;
  if (!f || fscanf(f, "P6 %d %d %d", &im->w, &im->h, &maxv) != 3 || maxv != 255 ||
      im->w <= 0 || im->h <= 0 || im->w > 16384 || im->h > 16384 || fgetc(f) == EOF) {
    fprintf(stderr, "nudge-viewpix: %s is not an 8-bit P6 PPM\n", path);
    if (f) fclose(f);
    return -1;
  }
  const size_t n = (size_t)im->w * im->h * 3;
  im->px = malloc(n);
  const int ok = im->px && fread(im->px, 1, n, f) == n;
  fclose(f);
  if (!ok) fprintf(stderr, "nudge-viewpix: %s is cut short\n", path);
  return ok ? 0 : -1;
}

static int is_class(const char *c, int r, int g, int b) {
  if (!strcmp(c, "blue")) return b > 110 && b > r + 60 && b > g + 35;
  if (!strcmp(c, "green")) return g > 100 && g > r + 35 && g > b + 35;
  if (!strcmp(c, "red")) return r > 110 && r > g + 80 && r > b + 80;
  if (!strcmp(c, "orange")) return r > 150 && g > 90 && r > g + 30 && g > b + 30;
  if (!strcmp(c, "yellow")) return r > 150 && g > 130 && b < 90 && r - g < 60;
  if (!strcmp(c, "white")) return r > 200 && g > 200 && b > 200;
  if (!strcmp(c, "cyan")) return g > 110 && b > 110 && r < g - 60 && r < b - 60;
  return -1;
}

int main(int argc, char **argv) {
  image a = {0}, b = {0};
  if (argc >= 4 && !strcmp(argv[1], "blob")) {
    if (load(argv[2], &a)) return 1;
    int x0 = 0, y0 = 0, x1 = a.w, y1 = a.h;
    if (argc == 8) {
      x0 = atoi(argv[4]), y0 = atoi(argv[5]), x1 = atoi(argv[6]), y1 = atoi(argv[7]);
    } else if (argc != 4) {
      return 2;
    }
    if (is_class(argv[3], 0, 0, 0) < 0) {
      fprintf(stderr, "nudge-viewpix: unknown colour '%s'\n", argv[3]);
      return 2;
    }
    long n = 0;
    double sx = 0, sy = 0;
    for (int y = y0 < 0 ? 0 : y0; y < y1 && y < a.h; y++)
      for (int x = x0 < 0 ? 0 : x0; x < x1 && x < a.w; x++) {
        const unsigned char *p = a.px + 3 * ((size_t)y * a.w + x);
        if (is_class(argv[3], p[0], p[1], p[2]) == 1) {
          n++;
          sx += x;
          sy += y;
        }
      }
    printf("blob_n %ld count\nblob_x %.1f px\nblob_y %.1f px\n", n, n ? sx / n : -1.0,
           n ? sy / n : -1.0);
    return 0;
  }
  if (argc == 4 && !strcmp(argv[1], "diff")) {
    if (load(argv[2], &a) || load(argv[3], &b)) return 1;
    if (a.w != b.w || a.h != b.h) {
      printf("diff_pixels %ld count\ndiff_max 255 level\n", (long)a.w * a.h);
      return 0;
    }
    long n = 0;
    int m = 0;
    for (long i = 0; i < (long)a.w * a.h; i++) {
      int d = 0;
      for (int k = 0; k < 3; k++) {
        const int e = abs(a.px[3 * i + k] - b.px[3 * i + k]);
        if (e > d) d = e;
      }
      n += d > 0;
      if (d > m) m = d;
    }
    printf("diff_pixels %ld count\ndiff_max %d level\n", n, m);
    return 0;
  }
  if (argc == 5 && !strcmp(argv[1], "at")) {
    if (load(argv[2], &a)) return 1;
    const int x = atoi(argv[3]), y = atoi(argv[4]);
    if (x < 0 || y < 0 || x >= a.w || y >= a.h) return 2;
    const unsigned char *p = a.px + 3 * ((size_t)y * a.w + x);
    printf("rgb %d %d %d\n", p[0], p[1], p[2]);
    return 0;
  }
  fprintf(stderr, "usage: nudge-viewpix blob FILE COLOUR [X0 Y0 X1 Y1] | diff A B | at FILE X Y\n");
  return 2;
}
