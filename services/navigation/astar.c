/* A* (or Dijkstra, heuristic off) on an 8-connected grid with per-cell costs.
 *
 * cost[ny*nx]: < 0 lethal (never entered), else the cell's cost c >= 0.
 * Edge u -> v: step * (1 + weight * (c[u] + c[v]) / 2), step 1 or sqrt(2) (cells);
 * a diagonal needs both cells it cuts past to be non-lethal. The heuristic is the
 * octile distance, consistent because every edge costs at least its step.
 * Returns the path length in cells written to path (goal first) or -1 (no path),
 * -2 (path longer than max_path), -3 (out of memory).
 * Built at install (setup.py) and loaded by services/navigation/native.py with ctypes;
 * no Python headers needed.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct { double f; double g; int node; } item;

static void push(item *h, long *n, item it) {
    long i = (*n)++;
    while (i > 0) {
        long p = (i - 1) / 2;
        if (h[p].f < it.f || (h[p].f == it.f && h[p].g >= it.g)) break;
        h[i] = h[p];
        i = p;
    }
    h[i] = it;
}

static item pop(item *h, long *n) {
    item top = h[0], last = h[--(*n)];
    long i = 0;
    for (;;) {
        long c = 2 * i + 1;
        if (c >= *n) break;
        if (c + 1 < *n && (h[c + 1].f < h[c].f || (h[c + 1].f == h[c].f && h[c + 1].g > h[c].g))) c++;
        if (last.f < h[c].f || (last.f == h[c].f && last.g >= h[c].g)) break;
        h[i] = h[c];
        i = c;
    }
    h[i] = last;
    return top;
}

static double octile(int ay, int ax, int by, int bx) {
    double dx = fabs((double)(ax - bx)), dy = fabs((double)(ay - by));
    return (dx > dy) ? dx + (M_SQRT2 - 1.0) * dy : dy + (M_SQRT2 - 1.0) * dx;
}

long astar(int ny, int nx, const float *cost, double weight, int start, int goal,
           int heuristic, int *path, long max_path, double *cost_out, long *expanded_out) {
    static const int DY[8] = {-1, -1, -1, 0, 0, 1, 1, 1};
    static const int DX[8] = {-1, 0, 1, -1, 1, -1, 0, 1};
    long n = (long)ny * nx, hn = 0, cap = 4096, expanded = 0, len = -1;
    double *g = malloc(sizeof(double) * n);
    int *parent = malloc(sizeof(int) * n);
    unsigned char *closed = calloc(n, 1);
    item *heap = malloc(sizeof(item) * cap);
    if (!g || !parent || !closed || !heap) { len = -3; goto done; }
    for (long i = 0; i < n; i++) g[i] = INFINITY;
    int gy = goal / nx, gx = goal % nx;
    g[start] = 0.0;
    parent[start] = -1;
    push(heap, &hn, (item){heuristic ? octile(start / nx, start % nx, gy, gx) : 0.0, 0.0, start});
    while (hn > 0) {
        item it = pop(heap, &hn);
        int u = it.node;
        if (closed[u]) continue;
        closed[u] = 1;
        expanded++;
        if (u == goal) break;
        int uy = u / nx, ux = u % nx;
        double cu = cost[u];
        for (int k = 0; k < 8; k++) {
            int vy = uy + DY[k], vx = ux + DX[k];
            if (vy < 0 || vy >= ny || vx < 0 || vx >= nx) continue;
            int v = vy * nx + vx;
            if (closed[v] || cost[v] < 0.0f) continue;
            double step = 1.0;
            if (DY[k] && DX[k]) {
                if (cost[uy * nx + vx] < 0.0f || cost[vy * nx + ux] < 0.0f) continue;
                step = M_SQRT2;
            }
            double ng = g[u] + step * (1.0 + weight * 0.5 * (cu + cost[v]));
            if (ng < g[v]) {
                g[v] = ng;
                parent[v] = u;
                if (hn >= cap) {
                    item *grown = realloc(heap, sizeof(item) * cap * 2);
                    if (!grown) { len = -3; goto done; }
                    heap = grown;
                    cap *= 2;
                }
                push(heap, &hn, (item){ng + (heuristic ? octile(vy, vx, gy, gx) : 0.0), ng, v});
            }
        }
    }
    if (closed[goal]) {
        len = 0;
        for (int v = goal; v != -1; v = parent[v]) {
            if (len >= max_path) { len = -2; break; }
            path[len++] = v;
        }
        *cost_out = g[goal];
    }
done:
    *expanded_out = expanded;
    free(g); free(parent); free(closed); free(heap);
    return len;
}
