!1000 = distinct !{}
!1002 = distinct !{!1002, !1003}
!1003 = !{!"llvm.loop.parallel_accesses", !1000}
!0 = !{}
!900000 = distinct !{!900000, !"simgrad fields"}
!900002 = distinct !{!900002, !900000, !"tree 0 byte 0"}
!900003 = !{!900002}
!900004 = !{}
define internal void @sg_kernel_task1(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
entry:
  %ctx = load ptr, ptr %clo
  %cap.1 = getelementptr i64, ptr %clo, i64 1
  %capv.2 = load float, ptr %cap.1
  %lo.3 = trunc i64 %lo to i32
  %hi.4 = trunc i64 %hi to i32
  %cp.16 = getelementptr i64, ptr %ctx, i64 0
  %cv.17 = load ptr, ptr %cp.16
  %rp.18 = getelementptr ptr, ptr %cv.17, i64 0
  %root.19 = load ptr, ptr %rp.18, !invariant.load !0, !dereferenceable !{i64 64}, !align !{i64 64}
  br label %pre.5
pre.5:
  br label %head.6
head.6:
  %i.10 = phi i32 [%lo.3, %pre.5], [%inext.11, %latch.8]
  %c.12 = icmp slt i32 %i.10, %hi.4
  br i1 %c.12, label %body.7, label %done.9
body.7:
  %cv.13 = sext i32 %i.10 to i64
  %v.14 = mul nuw nsw i64 %cv.13, 4
  %ptr.15 = getelementptr inbounds i8, ptr %root.19, i64 %v.14
  %cv.20 = sitofp i32 %i.10 to float
  %v.21 = fmul nsz float %capv.2, %cv.20
  store float %v.21, ptr %ptr.15, !alias.scope !900003, !noalias !900004, !llvm.access.group !1000
  br label %latch.8
latch.8:
  %inext.11 = add i32 %i.10, 1
  br label %head.6, !llvm.loop !1002
done.9:
  ret void
}
define void @sg_kernel(ptr %ctx) {
entry:
  %cp.1 = getelementptr i64, ptr %ctx, i64 8
  %cv.2 = load ptr, ptr %cp.1
  store atomic i32 0, ptr %cv.2 monotonic, align 4
  %cp.3 = getelementptr i64, ptr %ctx, i64 10
  %cv.4 = load float, ptr %cp.3
  %clo.5 = alloca [2 x i64], align 8
  %cp.9 = getelementptr i64, ptr %ctx, i64 3
  %cv.10 = load ptr, ptr %cp.9
  store ptr %ctx, ptr %clo.5
  %cap.6 = getelementptr i64, ptr %clo.5, i64 1
  store float %cv.4, ptr %cap.6
  %b.7 = sext i32 0 to i64
  %e.8 = sext i32 16 to i64
  call void %cv.10(ptr @sg_kernel_task1, ptr %clo.5, i64 %b.7, i64 %e.8, i64 1024)
  %cancel.11 = load atomic i32, ptr %cv.2 monotonic, align 4
  %cancelled.12 = icmp ne i32 %cancel.11, 0
  br i1 %cancelled.12, label %stop.13, label %go.14
stop.13:
  call void @sg_report(ptr %ctx, i64 -1, i64 0)
  ret void
go.14:
  ret void
}

define internal void @sg_report(ptr %ctx, i64 %code, i64 %value) noinline {
  %ep = getelementptr i64, ptr %ctx, i64 1
  %err = load ptr, ptr %ep
  %r = cmpxchg ptr %err, i64 0, i64 %code monotonic monotonic
  %ok = extractvalue { i64, i1 } %r, 1
  br i1 %ok, label %store, label %done
store:
  %vp = getelementptr i64, ptr %err, i64 1
  store i64 %value, ptr %vp
  br label %done
done:
  ret void
}

define internal i32 @sg_rand_u32(ptr %ctx, i32 %tid) {
  %rp = getelementptr i64, ptr %ctx, i64 2
  %base = load ptr, ptr %rp
  %off = mul i32 %tid, 16
  %s = getelementptr i8, ptr %base, i32 %off
  %p1 = getelementptr i32, ptr %s, i32 1
  %p2 = getelementptr i32, ptr %s, i32 2
  %p3 = getelementptr i32, ptr %s, i32 3
  %x = load i32, ptr %s
  %y = load i32, ptr %p1
  %z = load i32, ptr %p2
  %w = load i32, ptr %p3
  %t0 = shl i32 %x, 11
  %t = xor i32 %x, %t0
  %t1 = lshr i32 %t, 8
  %t2 = xor i32 %t, %t1
  %w1 = lshr i32 %w, 19
  %w2 = xor i32 %w, %w1
  %n = xor i32 %w2, %t2
  store i32 %y, ptr %s
  store i32 %z, ptr %p1
  store i32 %w, ptr %p2
  store i32 %n, ptr %p3
  ret i32 %n
}

