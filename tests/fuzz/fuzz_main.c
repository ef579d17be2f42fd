/* Replay driver: runs a fuzz target's LLVMFuzzerTestOneInput over every file of the
 * directories (or files) named on the command line, without libFuzzer, so that ctest
 * replays the seed corpus and every saved crash with the ordinary compiler (and under
 * the sanitizers in build-asan). Fails on a missing path or when there is nothing to
 * replay: a corpus that silently vanished must not pass. */
#define _GNU_SOURCE
#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "fuzz.h"

/* Run the target on file path; 0, or -1 if it cannot be read. Each input gets a buffer
 * of exactly its size, as libFuzzer gives it, so reads past the end are caught. */
static int run_file(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    fprintf(stderr, "fuzz_main: cannot open %s: %s\n", path, strerror(errno));
    return -1;
  }
  struct stat st;
  if (fstat(fileno(f), &st) || st.st_size < 0) {
    fprintf(stderr, "fuzz_main: cannot stat %s: %s\n", path, strerror(errno));
    fclose(f);
    return -1;
  }
  const size_t size = (size_t)st.st_size;
  uint8_t *data = malloc(size ? size : 1);
  if (!data || fread(data, 1, size, f) != size) {
    fprintf(stderr, "fuzz_main: cannot read %s\n", path);
    free(data);
    fclose(f);
    return -1;
  }
  fclose(f);
  LLVMFuzzerTestOneInput(data, size);
  free(data);
  return 0;
}

static int by_name(const struct dirent **a, const struct dirent **b) {
  return strcmp((*a)->d_name, (*b)->d_name);
}

static int skip_dot(const struct dirent *e) { return e->d_name[0] != '.'; }

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s DIR|FILE...\n  runs the fuzz target once on every file\n",
            argv[0]);
    return 2;
  }
  long inputs = 0;
  for (int a = 1; a < argc; a++) {
    struct stat st;
    if (stat(argv[a], &st)) {
      fprintf(stderr, "fuzz_main: %s: %s\n", argv[a], strerror(errno));
      return 1;
    }
    if (!S_ISDIR(st.st_mode)) {
      if (run_file(argv[a])) return 1;
      inputs++;
      continue;
    }
    struct dirent **names;
    const int n = scandir(argv[a], &names, skip_dot, by_name);  /* sorted: reproducible */
    if (n < 0) {
      fprintf(stderr, "fuzz_main: cannot list %s: %s\n", argv[a], strerror(errno));
      return 1;
    }
    int rc = 0;
    for (int i = 0; i < n; i++) {
      char path[4096];
      snprintf(path, sizeof path, "%s/%s", argv[a], names[i]->d_name);
      if (!rc && stat(path, &st) == 0 && S_ISREG(st.st_mode)) {
        rc = run_file(path);
        inputs++;
      }
      free(names[i]);
    }
    free(names);
    if (rc) return 1;
  }
  printf("fuzz_main: %s: %ld inputs replayed, no invariant broken\n", argv[0], inputs);
  if (inputs == 0) {
    fprintf(stderr, "fuzz_main: no inputs found: the corpus is missing\n");
    return 1;
  }
  return 0;
}
