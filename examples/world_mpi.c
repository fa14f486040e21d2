/* world_mpi.c - one terrainnet world computed by several MPI processes (on one machine or many):
   rank r of n writes the tiles k = r, r + n, r + 2n, ... (row-major over the grid), then rank 0
   writes world.vrt and manifest.txt. The tiles are byte-for-byte those of
   `terrainnet world SPEC -o DIR`, since a tile depends only on the SPEC and its position.
   Build: make mpi   (needs mpicc; Debian: openmpi-bin libopenmpi-dev)
   Run:   mpirun -np 4 bin/world_mpi SPEC DIR [TILE]
   DIR must be on a file system every rank sees (NFS, Lustre, ...). Each rank uses one thread;
   start one rank per core. */
#include <mpi.h>
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <sys/stat.h>

int main(int argc, char **argv)
{
    tn_world w;
    tn_world_opts wo = {0, NULL};
    tn_world_run_opts ro = {0, 0, 0, 0, 0, 0};
    tn_world_run_stats s = {0, 0, 0.0};
    int rank, size, bad = 0, any_bad = 0, present = 0, written = 0;
    tn_status st;
    MPI_Init(&argc, &argv);
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
    if (argc < 3 || argc > 4) {
        if (rank == 0) fprintf(stderr, "usage: mpirun -np N %s SPEC DIR [TILE]\n", argv[0]);
        MPI_Finalize();
        return 2;
    }
    if (argc == 4) wo.tile = atoi(argv[3]);
    tn_set_threads(1);
    if ((st = tn_world_load(&w, argv[1], &wo))) {
        fprintf(stderr, "rank %d: %s: %s\n", rank, tn_status_string(st), tn_last_error());
        MPI_Abort(MPI_COMM_WORLD, 1);
    }
    if (rank == 0) mkdir(argv[2], 0777); /* an existing directory is fine */
    MPI_Barrier(MPI_COMM_WORLD);
    ro.part = rank;
    ro.parts = size;
    if ((st = tn_world_write_tiles(argv[2], &w, &ro, &s))) {
        fprintf(stderr, "rank %d: %s: %s\n", rank, tn_status_string(st), tn_last_error());
        bad = 1;
    }
    printf("rank %d of %d: %d tiles written, %d already there, %.2f s\n", rank, size, s.written, s.skipped, s.seconds);
    MPI_Allreduce(&bad, &any_bad, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    MPI_Reduce(&s.written, &written, 1, MPI_INT, MPI_SUM, 0, MPI_COMM_WORLD);
    if (rank == 0 && !any_bad) {
        if ((st = tn_world_write_index(argv[2], &w, &present))) {
            fprintf(stderr, "rank 0: index: %s\n", tn_last_error());
            any_bad = 1;
        } else {
            printf("world: %d tiles written by %d ranks; %d of %d present; %s/world.vrt\n", written, size, present, w.rows * w.cols,
                   argv[2]);
        }
    }
    tn_world_free(&w);
    MPI_Finalize();
    return any_bad;
}
