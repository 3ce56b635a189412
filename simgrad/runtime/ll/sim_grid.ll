; The simulated GPU's launch (runtime/device.py HostDriver.launch): `fn` over grid x block threads, the
; blocks spread over the thread pool (its parallel_for is read from the context, slot ${pfor_slot}), each
; block's threads one after another in the block runner (sim_blocks.ll, linked beside it).

define void @simgrad_sim_grid(ptr %ctx, ptr %fn, i64 %block, i64 %grid) {
entry:
  %pfp = getelementptr i64, ptr %ctx, i64 ${pfor_slot}
  %pfor = load ptr, ptr %pfp
  %clo = alloca [4 x i64], align 8
  store ptr %ctx, ptr %clo
  %fp = getelementptr i64, ptr %clo, i64 1
  store ptr %fn, ptr %fp
  %bp = getelementptr i64, ptr %clo, i64 2
  store i64 %block, ptr %bp
  %gp = getelementptr i64, ptr %clo, i64 3
  store i64 %grid, ptr %gp
  call void %pfor(ptr @simgrad_sim_blocks, ptr %clo, i64 0, i64 %grid, i64 1)
  ret void
}
