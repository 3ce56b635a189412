; The simulated GPU's block runner (codegen/nvptx.py `_sim_entry`): a thread-pool task over block indices
; [lo, hi); the closure holds the context, the kernel entry, the block size and the grid size. Each block
; runs its threads one after another, each with its own special registers (tid, block, ntid, grid).
; Parameter: ${symbol}, the function's symbol.

define internal void @${symbol}(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
entry:
  %ctx = load ptr, ptr %clo
  %fp = getelementptr i64, ptr %clo, i64 1
  %fn = load ptr, ptr %fp
  %bp = getelementptr i64, ptr %clo, i64 2
  %block = load i64, ptr %bp
  %gp = getelementptr i64, ptr %clo, i64 3
  %grid = load i64, ptr %gp
  %sreg = alloca [4 x i32], align 4
  %p1 = getelementptr i32, ptr %sreg, i32 1
  %p2 = getelementptr i32, ptr %sreg, i32 2
  %p3 = getelementptr i32, ptr %sreg, i32 3
  %b32 = trunc i64 %block to i32
  %g32 = trunc i64 %grid to i32
  store i32 %b32, ptr %p1
  store i32 %g32, ptr %p3
  br label %bhead
bhead:
  %b = phi i64 [%lo, %entry], [%bnext, %tdone]
  %bc = icmp slt i64 %b, %hi
  br i1 %bc, label %bbody, label %exit
bbody:
  %bi = trunc i64 %b to i32
  store i32 %bi, ptr %p2
  br label %thead
thead:
  %t = phi i32 [0, %bbody], [%tnext, %tbody]
  %tc = icmp slt i32 %t, %b32
  br i1 %tc, label %tbody, label %tdone
tbody:
  store i32 %t, ptr %sreg
  call void %fn(ptr %ctx, ptr %sreg)
  %tnext = add i32 %t, 1
  br label %thead
tdone:
  %bnext = add i64 %b, 1
  br label %bhead
exit:
  ret void
}