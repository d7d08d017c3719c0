/* flock() refused with ENOLCK on files below $NOLOCK_DIR, as a mount without locks refuses it (tests/storage_tests/test_no_locks.py) */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <unistd.h>
/* flock() refused with ENOLCK on files below $NOLOCK_DIR, as a mount without locks refuses it */
int flock(int fd, int op) {
    static int (*real)(int, int);
    if (!real) real = (int (*)(int, int))dlsym(RTLD_NEXT, "flock");
    const char *dir = getenv("NOLOCK_DIR");
    char link[64], path[4096];
    snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
    ssize_t n = readlink(link, path, sizeof path - 1);
    if (dir && n > 0) {
        path[n] = 0;
        if (strncmp(path, dir, strlen(dir)) == 0) { errno = ENOLCK; return -1; }
    }
    return real(fd, op);
}
