; A captured launch sequence (runtime/launch.py run_sequence, used by lang/graph.py): `steps` holds n pairs
; {entry, ctx}; each entry(ctx) runs in order. It stops after the first kernel that reported an error (the
; error buffer's code word, `err`, is not 0) and returns that step's index; n when all ran.

define i64 @simgrad_run_sequence(ptr %steps, i64 %n, ptr %err) {
entry:
  br label %head
head:
  %k = phi i64 [0, %entry], [%next, %ok]
  %more = icmp slt i64 %k, %n
  br i1 %more, label %body, label %done
body:
  %i = shl i64 %k, 1
  %fp = getelementptr ptr, ptr %steps, i64 %i
  %fn = load ptr, ptr %fp
  %j = add i64 %i, 1
  %cp = getelementptr ptr, ptr %steps, i64 %j
  %ctx = load ptr, ptr %cp
  call void %fn(ptr %ctx)
  %code = load volatile i64, ptr %err
  %bad = icmp ne i64 %code, 0
  %next = add i64 %k, 1
  br i1 %bad, label %fail, label %ok
ok:
  br label %head
fail:
  ret i64 %k
done:
  ret i64 %n
}
